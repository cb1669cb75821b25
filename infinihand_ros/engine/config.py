"""Settings of the streaming engine (``config/engine.yaml``, section ``engine``)."""

from dataclasses import dataclass
from dataclasses import field
from pathlib import Path
from typing import Final

from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import load_config
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.metric_scale import MetricScaleConfig

ENGINE_SECTION: Final = 'engine'
MODES: Final = ('per_frame', 'windowed')


@dataclass(frozen=True)
class EngineConfig:
    """How the engine runs the model.

    Attributes:
        geometry: geometry-branch config, a name ('tiny', 'paper') or a YAML path.
        hand_branch: hand-branch config, a name ('tiny', 'paper') or a YAML path.
        mode: 'per_frame' (each frame out as soon as it is computed; lowest latency) or
            'windowed' (frames batched into windows, backbone and decoding pipelined).
        window: frames per window in windowed mode (the paper: 16).
        keyframe_interval: after the anchors, every this-many-th frame enters the memory.
        device: torch device ('cpu', 'cuda', 'cuda:1', ...).
        seed: seed of the weight initialisation when no trained weights are loaded.
        presence_threshold: a hand mask whose peak probability is below this is no detection.
        fov_range_deg: predicted fields of view are clamped to this range (the camera head's
            ReLU allows 0, which no camera has).
        metric_scale: running metric-scale estimate from the hands.
        checkpoint: our checkpoint directory (its configs win); None: seeded untrained weights.
        bundle_adjustment: run sparse BA in a background thread and correct the poses.
        ba_config: BA settings file; None: the package's ``config/ba.yaml``.

    """

    geometry: str = 'tiny'
    hand_branch: str = 'tiny'
    mode: str = 'per_frame'
    window: int = 16
    keyframe_interval: int = 1
    device: str = 'cpu'
    seed: int = 0
    presence_threshold: float = 0.5
    fov_range_deg: tuple[float, float] = (5.0, 170.0)
    metric_scale: MetricScaleConfig = field(default_factory=MetricScaleConfig)
    checkpoint: str | None = None
    bundle_adjustment: bool = False
    ba_config: str | None = None

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ConfigError(f'engine.mode must be one of {list(MODES)}, got {self.mode!r}')
        if self.window < 1 or self.keyframe_interval < 1:
            raise ConfigError(f'engine.window and engine.keyframe_interval must be >= 1, got '
                              f'{self.window} and {self.keyframe_interval}')
        if not 0.0 < self.fov_range_deg[0] < self.fov_range_deg[1] < 180.0:
            raise ConfigError(f'engine.fov_range_deg must be increasing within (0, 180), got '
                              f'{self.fov_range_deg}')
        if not 0.0 < self.presence_threshold < 1.0:
            raise ConfigError(f'engine.presence_threshold must be in (0, 1), got '
                              f'{self.presence_threshold}')


def load_engine_config(path: str | Path | None = None) -> EngineConfig:
    """Load ``config/engine.yaml`` (or ``path``)."""
    return load_config(path or config_dir() / 'engine.yaml', ENGINE_SECTION, EngineConfig)
