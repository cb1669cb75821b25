"""Settings of the engine's output stage: hand identity, one shape per side, smoothing."""

from dataclasses import dataclass
from dataclasses import field
from typing import Final

from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError

SMOOTHING_MODES: Final = ('none', 'one_euro')  # not 'off': YAML reads a bare off as false


@dataclass(frozen=True)
class SmoothingConfig:
    """One-Euro smoothing of the teleop outputs (parameters ``smoothing.*``)."""

    mode: str = 'none'
    min_cutoff_hz: float = 1.0
    beta: float = 0.0
    d_cutoff_hz: float = 1.0

    def __post_init__(self) -> None:
        if self.mode not in SMOOTHING_MODES:
            raise ConfigError(f'smoothing.mode: must be one of {list(SMOOTHING_MODES)}, got '
                              f'{self.mode!r}')
        require_positive('smoothing', min_cutoff_hz=self.min_cutoff_hz,
                         d_cutoff_hz=self.d_cutoff_hz)
        require_at_least('smoothing', 0.0, beta=self.beta)


@dataclass(frozen=True)
class IdentityConfig:
    """Per-side hand identity over time (parameters ``identity.*``)."""

    match_radius: float = 0.25
    max_gap_s: float = 0.5

    def __post_init__(self) -> None:
        require_positive('identity', match_radius=self.match_radius,
                         max_gap_s=self.max_gap_s)


@dataclass(frozen=True)
class ShapeConfig:
    """One hand shape per side over time (parameters ``shape.*``)."""

    enabled: bool = True
    min_confidence: float = 0.7
    min_samples: int = 10

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_confidence <= 1.0:
            raise ConfigError(f'shape.min_confidence: must be in [0, 1], got '
                              f'{self.min_confidence}')
        require_at_least('shape', 1, min_samples=self.min_samples)


@dataclass(frozen=True)
class OutputConfig:
    """The engine's output stage (``engine.output``), the same for every consumer.

    Attributes:
        identity: per-side hand identity over time.
        shape: one hand shape (MANO betas) per side over time.
        smoothing: One-Euro smoothing of the world-frame joints.

    """

    identity: IdentityConfig = field(default_factory=IdentityConfig)
    shape: ShapeConfig = field(default_factory=ShapeConfig)
    smoothing: SmoothingConfig = field(default_factory=SmoothingConfig)
