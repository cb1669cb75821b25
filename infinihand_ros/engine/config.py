"""Settings of the streaming engine: one tree of dataclasses, the only place defaults live.

Profiles, overrides and the generated ``config/engine.yaml`` are in ``engine/settings.py``.
``engine`` -> ``model`` (geometry and hand-branch configs, hand model incl. real MANO, weights)
-> ``detection`` -> ``metric_scale`` -> ``pose_track`` -> ``tracker`` -> ``bundle_adjustment``
(BA settings, or null for none). Every value is checked when it is built; errors name
the key, e.g. ``engine.model.hand_model.mano_dir`` or
``engine.bundle_adjustment.tracking.klt_window_px``.
In YAML, ``bundle_adjustment`` may be ``null`` (off), ``true`` (the package's
``config/ba.yaml``), a path to a BA YAML file, or the BA settings themselves.
"""

from dataclasses import dataclass
from dataclasses import field
from typing import Final

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.camera_tracker import TrackerConfig
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.metric_scale import MetricScaleConfig
from infinihand_ros.engine.output.config import OutputConfig
from infinihand_ros.engine.pacing import PacingConfig
from infinihand_ros.engine.pose_track import PoseTrackConfig
from infinihand_ros.mano.hand_model import HandModelConfig
import torch

ENGINE_SECTION: Final = 'engine'
MODES: Final = ('per_frame', 'windowed')
CAMERA_MOTIONS: Final = ('estimate', 'static')
LENS_WARMUPS: Final = ('beside', 'first')
CPU_PRECISIONS: Final = ('auto', 'fp32')


def check_device(name: str, key: str = 'engine.device') -> None:
    """Raise ConfigError unless ``name`` is a torch device this machine can run the model on.

    Args:
        name: 'cpu', 'cuda', 'cuda:N' (or another device type torch knows and has).
        key: the config key named in the error.

    """
    try:
        device = torch.device(name)
    except (RuntimeError, TypeError) as exc:
        raise ConfigError(f'{key}: {name!r} is not a torch device; use cpu, cuda or '
                          'cuda:N') from exc
    if device.type == 'meta':
        raise ConfigError(f'{key}: the meta device holds no data and cannot run the model; '
                          'use cpu or cuda')
    if device.type == 'cuda':
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if count == 0:
            raise ConfigError(f'{key}: {name!r} asked for, but this machine has no usable CUDA '
                              f'device (torch {torch.__version__}); use cpu')
        if device.index is not None and device.index >= count:
            raise ConfigError(f'{key}: {name!r} asked for, but only {count} CUDA device(s) '
                              f'exist (cuda:0..cuda:{count - 1})')
    elif device.type != 'cpu':
        raise ConfigError(f'{key}: device type {device.type!r} is not supported; use cpu or '
                          'cuda')


@dataclass(frozen=True)
class ModelSelection:
    """Which model the engine runs (section ``engine.model``).

    Attributes:
        geometry: geometry-branch config, a name ('tiny', 'tiny_336': the bundled model's,
            'paper') or a YAML path.
        hand_branch: hand-branch config, a name ('tiny', 'paper') or a YAML path.
        hand_model: the hand model (built-in skeleton, or real MANO from ``mano_dir``).
        checkpoint: a bundled model (``models/<name>``, with its card) or our whole-model
            checkpoint directory (its configs win); None: seeded weights.
        geometry_weights: a converted LingBot-Map/VGGT checkpoint directory for the geometry
            branch (``model/io/convert``), or None.
        crop_encoder_weights: a converted WiLoR checkpoint directory for the crop encoder, or
            None.
        seed: seed of every weight that no checkpoint provides.

    """

    geometry: str = 'tiny_336'
    hand_branch: str = 'tiny'
    hand_model: HandModelConfig = field(default_factory=HandModelConfig)
    checkpoint: str | None = 'tiny_synthetic'
    geometry_weights: str | None = None
    crop_encoder_weights: str | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        if self.checkpoint is not None and (self.geometry_weights or self.crop_encoder_weights):
            raise ConfigError('engine.model: give either checkpoint (a whole model) or '
                              'geometry_weights / crop_encoder_weights (parts), not both')

    @property
    def weights_name(self) -> str:
        """Return what the weights come from, for error messages."""
        return (f'checkpoint {self.checkpoint}' if self.checkpoint is not None
                else f'seeded untrained weights (seed {self.seed})')


@dataclass(frozen=True)
class DetectionConfig:
    """Hand detection and camera decoding (section ``engine.detection``).

    Attributes:
        presence_threshold: a hand mask whose peak probability is below this is no hand.
        fov_range_deg: predicted fields of view are clamped to this range (the camera head's
            ReLU allows 0, which no camera has).
        peak_region: box only the connected region around each hand mask's peak, so stray pixels
            do not stretch the box (ours; the paper boxes every pixel above the threshold).
        region_join_px: with ``peak_region``, mask fragments up to ``2 * region_join_px + 1``
            model-input pixels apart count as one region, so a hand whose mask breaks into
            pieces is boxed whole (ours; 14: one patch; 0: plain 8-connectivity).

    """

    presence_threshold: float = 0.5
    fov_range_deg: tuple[float, float] = (5.0, 170.0)
    peak_region: bool = True
    region_join_px: int = 14

    def __post_init__(self) -> None:
        if not 0.0 < self.fov_range_deg[0] < self.fov_range_deg[1] < 180.0:
            raise ConfigError(f'engine.detection.fov_range_deg must be increasing within '
                              f'(0, 180), got {self.fov_range_deg}')
        if not 0.0 < self.presence_threshold < 1.0:
            raise ConfigError(f'engine.detection.presence_threshold must be in (0, 1), got '
                              f'{self.presence_threshold}')
        if self.region_join_px < 0:  # the loader has checked it is an int
            raise ConfigError(f'engine.detection.region_join_px must be >= 0 pixels, got '
                              f'{self.region_join_px}')


@dataclass(frozen=True)
class EngineConfig:
    """How the engine runs the model.

    Attributes:
        mode: 'per_frame' (each frame out as soon as it is computed; lowest latency) or
            'windowed' (frames batched into windows, geometry and hands pipelined).
        window: frames per window in windowed mode (the paper: 16).
        keyframe_interval: after the anchors, every this-many-th frame enters the memory.
        geometry_interval: in per-frame mode, for a moving camera whose hands come from
            outside the model (MediaPipe), the geometry branch runs on every this-many-th frame
            after the anchors (and on any frame whose tracker needs depth: a new reference, a
            restart); the frames between are tracked from the image alone with the last
            intrinsics. Without BA, a frame whose tracker holds the camera is answered before
            its geometry branch runs (``StreamingEngine.catch_up``). 'auto': chosen as the
            stream runs from what a frame and the geometry branch cost on this machine, so that
            frames at the input's rate are answered within ``pacing.utilisation`` of the frame
            period (``engine/pacing.py``); 1: every frame, geometry first (the reference path).
        geometry_lag: for such a frame answered first, 0: the pose track takes its geometry
            branch's outputs before the next frame (``catch_up`` runs it in the caller's
            thread); n >= 1: n frames later (the n frames after it are tracked from the image
            too), so a live caller's ``catch_up`` runs it in a worker thread, paused while a
            frame is pushed, and the next frames' answers do not wait for it (lower latency;
            slightly less exact tracking, as a new tracker reference comes n frames later).
            Held below the geometry interval (when that is above 1).
        pacing: how ``geometry_interval: auto`` chooses the interval.
        device: torch device ('cpu', 'cuda', 'cuda:1', ...), checked at load.
        cpu_precision: on the CPU, 'auto' runs the aggregator in bf16 where the CPU computes
            bf16 natively (AVX512-BF16 or AMX, checked at start-up; float32 elsewhere); 'fp32'
            is the float32 reference path. CUDA follows the model's ``autocast_bf16``.
        model: the model and its weights.
        detection: hand detection thresholds and the FoV clamp.
        metric_scale: running metric-scale estimate from the hands.
        pose_track: the pose track's memory and scale smoothing.
        tracker: the per-frame camera tracker (the pose track's front end).
        bundle_adjustment: sparse BA settings (BA runs in the background and corrects the
            poses), or None for no BA.
        camera_motion: 'estimate' (a moving camera) or 'static' (a fixed camera: its pose is
            the world frame, hands are placed with the identity pose, no BA).
        output: the output stage (hand identity, shared shape, smoothing).
        hands: where the hands come from (the paper's hand branch or MediaPipe) and which count.
        depth_maps: give every keyframe's metric depth map in ``FrameResult.depth`` (the depth
            head then runs on every keyframe); False: only keyframes sent to BA carry one, and
            the depth head runs only where a depth is used.
        lens_frames: one lens per stream, with hands found outside the model and no given
            intrinsics: a moving camera holds the median of the intrinsics the model predicted
            on its first block (the anchor frames); a fixed camera the median of this many
            frames' predictions (``lens_warmup``), and runs the geometry branch on those only
            (it has nothing else to give it); 0: intrinsics predicted on every frame (a zoom
            lens).
        lens_warmup: a fixed camera's lens (``lens_frames``): 'beside' (live): its frames
            go out at once, with a provisional lens (flagged ``provisional_intrinsics``) until
            the predictions made beside the stream settle it; 'first' (offline, results
            independent of timing): its first ``lens_frames`` frames are predicted in turn,
            each given the median so far (flagged too).
        restart_after_s: a frame stamped more than this before the last accepted one starts
            a new stream in ``push`` (a replay looping, a camera restarting, normal stamps
            after a far-future one: the engine resets and the world frame restarts at it); one
            stamped less far back, or not after it, is out of order (refused: ``InputError``);
            0.0: never restart, s.

    """

    mode: str = 'per_frame'
    window: int = 16
    keyframe_interval: int = 1
    geometry_interval: int | str = 'auto'
    geometry_lag: int = 2
    pacing: PacingConfig = field(default_factory=PacingConfig)
    device: str = 'cpu'
    cpu_precision: str = 'auto'
    model: ModelSelection = field(default_factory=ModelSelection)
    detection: DetectionConfig = field(default_factory=DetectionConfig)
    metric_scale: MetricScaleConfig = field(default_factory=MetricScaleConfig)
    pose_track: PoseTrackConfig = field(default_factory=PoseTrackConfig)
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    bundle_adjustment: BAConfig | None = None
    camera_motion: str = 'estimate'
    output: OutputConfig = field(default_factory=OutputConfig)
    hands: HandsConfig = field(default_factory=HandsConfig)
    depth_maps: bool = False
    lens_frames: int = 16
    lens_warmup: str = 'beside'
    restart_after_s: float = 1.0

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ConfigError(f'engine.mode must be one of {list(MODES)}, got {self.mode!r}')
        if self.cpu_precision not in CPU_PRECISIONS:
            raise ConfigError(f'engine.cpu_precision must be one of {list(CPU_PRECISIONS)}, '
                              f'got {self.cpu_precision!r}')
        if self.lens_warmup not in LENS_WARMUPS:
            raise ConfigError(f'engine.lens_warmup must be one of {list(LENS_WARMUPS)}, got '
                              f'{self.lens_warmup!r}')
        if self.camera_motion not in CAMERA_MOTIONS:
            raise ConfigError(f'engine.camera_motion must be one of {list(CAMERA_MOTIONS)}, '
                              f'got {self.camera_motion!r}')
        require_at_least('engine', 1, window=self.window,
                         keyframe_interval=self.keyframe_interval)
        if self.geometry_interval != 'auto':
            if isinstance(self.geometry_interval, str):
                raise ConfigError(f"engine.geometry_interval must be 'auto' or a number of "
                                  f'frames >= 1, got {self.geometry_interval!r}')
            require_at_least('engine', 1, geometry_interval=self.geometry_interval)
        require_at_least('engine', 0, lens_frames=self.lens_frames)
        require_at_least('engine', 0, geometry_lag=self.geometry_lag)
        require_at_least('engine', 0.0, restart_after_s=self.restart_after_s)
        if (self.geometry_interval != 'auto' and self.geometry_interval > 1
                and self.geometry_lag >= self.geometry_interval):
            raise ConfigError(f'engine.geometry_lag ({self.geometry_lag}) must be below '
                              f'engine.geometry_interval ({self.geometry_interval}): set it to '
                              f'{self.geometry_interval - 1} or less (the outputs of a '
                              'geometry frame are taken in before the next one runs)')
        check_device(self.device)
