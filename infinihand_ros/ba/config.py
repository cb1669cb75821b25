"""Configuration of the bundle-adjustment components (``config/ba.yaml``).

Each config refuses at construction (so at load, naming the key such as
``ba.tracking.klt_window_px``) the values that would make every BA call fail: NaN or infinite
numbers, counts and thresholds outside the ranges OpenCV and the solver accept.
"""

import dataclasses
from dataclasses import dataclass
from dataclasses import field
from pathlib import Path
from typing import Final

from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import load_config
from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.config import require_finite
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError

#: Top-level section of ``config/ba.yaml`` holding the ``BAConfig`` fields.
BA_SECTION: Final = 'ba'
#: Smallest KLT window side OpenCV's calcOpticalFlowPyrLK accepts (it asserts winSize > 2).
MIN_KLT_WINDOW_PX: Final = 3
#: Bits in an ORB descriptor: the largest meaningful Hamming distance.
ORB_DESCRIPTOR_BITS: Final = 256
#: Largest CPU niceness of the BA process (Linux's lowest priority).
MAX_NICENESS: Final = 19
#: ``ba.worker.when_behind`` values: drop the oldest waiting selection, or wait for room.
WHEN_BEHIND: Final = ('drop', 'wait')


def _require_finite_fields(owner: str, config: object) -> None:
    """Raise ConfigError naming the first float field of the dataclass ``config`` not finite."""
    require_finite(owner, **{item.name: getattr(config, item.name)
                             for item in dataclasses.fields(config)
                             if isinstance(getattr(config, item.name), float)})


@dataclass(frozen=True)
class PoolConfig:
    """Binary keyframe pool (paper appendix C; the paper gives no values for N and K).

    Attributes:
        trigger: N, BA runs when the pool holds more than N entries.
        stride: K, every K-th pool entry from the oldest is selected.
        min_interval_s: a keyframe enters the pool at least this long after the one before
            (the stream's other keyframes skip BA and its depth maps): baselines BA can use,
            and BA's cost independent of the frame rate.

    """

    trigger: int = 32
    stride: int = 2
    min_interval_s: float = 0.1

    def __post_init__(self) -> None:
        require_at_least('ba.pool', 1, trigger=self.trigger)
        require_at_least('ba.pool', 2, stride=self.stride)
        require_at_least('ba.pool', 0.0, min_interval_s=self.min_interval_s)


@dataclass(frozen=True)
class SolverConfig:
    """Levenberg-Marquardt BA over keyframe poses and per-track inverse depths.

    Attributes:
        irls_iterations: LM iterations with Huber weights before the outlier gate.
        max_iterations: LM iterations of plain least squares after the gate.
        huber_px: Huber threshold on the reprojection error norm (px).
        gate_px: observations with a larger reprojection error after IRLS are dropped (px).
        depth_prior_rel_sigma: depth prior sigma as a fraction of the depth (at confidence 1).
        rel_pose_sigma_m: sigma of the relative-pose prior's translation (m); <= 0 disables it.
        rel_pose_sigma_rad: sigma of the relative-pose prior's rotation (rad).
        initial_damping: LM damping (Marquardt, relative to the diagonal) at the start.
        min_relative_decrease: stop when the cost decreases by less than this fraction.
        min_inverse_depth: inverse depths are kept above this (1/m).
        lens_focal_sigma: prior sigma of the shared lens's log focal scale around the
            keyframes' median focal length; 0 holds the focal length.
        lens_k1_sigma: prior sigma of the shared lens's radial coefficient k1 around 0 (a real
            lens the intrinsics do not describe); 0 holds the pinhole.
        holdout_every: every n-th track is kept out of the fit; a result is used only where it
            fits those tracks better than its start (``ba.validation``); 0: no check.
        holdout_min_gain: ... by at least this share of the start's held-out cost, in [0, 1).

    """

    irls_iterations: int = 4
    max_iterations: int = 6
    huber_px: float = 1.5
    gate_px: float = 3.0
    depth_prior_rel_sigma: float = 0.2
    rel_pose_sigma_m: float = 0.01
    rel_pose_sigma_rad: float = 0.005
    initial_damping: float = 1e-4
    min_relative_decrease: float = 1e-4
    min_inverse_depth: float = 1e-3
    lens_focal_sigma: float = 0.1
    lens_k1_sigma: float = 0.2
    holdout_every: int = 5
    holdout_min_gain: float = 0.3

    def __post_init__(self) -> None:
        owner = 'ba.solver'
        _require_finite_fields(owner, self)
        require_at_least(owner, 0, irls_iterations=self.irls_iterations,
                         min_relative_decrease=self.min_relative_decrease,
                         lens_focal_sigma=self.lens_focal_sigma,
                         lens_k1_sigma=self.lens_k1_sigma, holdout_every=self.holdout_every)
        if not 0.0 <= self.holdout_min_gain < 1.0:
            raise ConfigError(f'{owner}.holdout_min_gain: must be in [0, 1), got '
                              f'{self.holdout_min_gain!r}')
        if self.holdout_every == 1:
            raise ConfigError(f'{owner}.holdout_every: 1 would hold out every track; use 0 (no '
                              'check) or at least 2')
        require_at_least(owner, 1, max_iterations=self.max_iterations)
        require_positive(owner, huber_px=self.huber_px, gate_px=self.gate_px,
                         depth_prior_rel_sigma=self.depth_prior_rel_sigma,
                         rel_pose_sigma_rad=self.rel_pose_sigma_rad,
                         initial_damping=self.initial_damping,
                         min_inverse_depth=self.min_inverse_depth)


@dataclass(frozen=True)
class TrackingConfig:
    """Correspondences between keyframes: KLT tracks, ORB re-links, RANSAC.

    Attributes:
        max_corners: corners detected per keyframe for KLT.
        corner_quality: goodFeaturesToTrack quality level, in (0, 1).
        min_corner_distance_px: minimum distance between detected corners (px).
        klt_window_px: KLT window side (px), at least ``MIN_KLT_WINDOW_PX``.
        klt_levels: KLT pyramid levels above the base image.
        klt_iterations: most LK iterations per pyramid level.
        klt_epsilon_px: LK stops at a level when its update is smaller than this (px).
        fb_threshold_px: forward-backward KLT error above which a track is cut (px).
        hand_margin_px: hand masks are dilated by this much before excluding pixels (px).
        ransac_threshold_px: fundamental-matrix RANSAC inlier threshold (px).
        orb_features: ORB keypoints per keyframe.
        orb_max_hamming: largest Hamming distance of an accepted ORB match (0..256).
        orb_max_gap: ORB matches each keyframe to the selected keyframes 2..gap places older.
        min_depth_m: depths outside [min_depth_m, max_depth_m] give no track (m).
        max_depth_m: see min_depth_m.

    """

    max_corners: int = 200
    corner_quality: float = 0.01
    min_corner_distance_px: float = 10.0
    klt_window_px: int = 15
    klt_levels: int = 3
    klt_iterations: int = 10
    klt_epsilon_px: float = 0.03
    fb_threshold_px: float = 1.0
    hand_margin_px: int = 10
    ransac_threshold_px: float = 1.0
    orb_features: int = 400
    orb_max_hamming: int = 48
    orb_max_gap: int = 2
    min_depth_m: float = 0.05
    max_depth_m: float = 30.0

    def __post_init__(self) -> None:
        owner = 'ba.tracking'
        _require_finite_fields(owner, self)
        require_at_least(owner, 8, max_corners=self.max_corners, orb_features=self.orb_features)
        require_at_least(owner, MIN_KLT_WINDOW_PX, klt_window_px=self.klt_window_px)
        require_at_least(owner, 1, klt_iterations=self.klt_iterations)
        require_at_least(owner, 0, klt_levels=self.klt_levels, hand_margin_px=self.hand_margin_px,
                         min_corner_distance_px=self.min_corner_distance_px,
                         orb_max_hamming=self.orb_max_hamming, orb_max_gap=self.orb_max_gap)
        require_positive(owner, klt_epsilon_px=self.klt_epsilon_px,
                         fb_threshold_px=self.fb_threshold_px,
                         ransac_threshold_px=self.ransac_threshold_px,
                         min_depth_m=self.min_depth_m)
        # goodFeaturesToTrack keeps corners strictly above quality x the best corner's score,
        # so 1 (or more) finds none and 0 is refused by OpenCV.
        if not 0.0 < self.corner_quality < 1.0:
            raise ConfigError(f'{owner}.corner_quality: must be in (0, 1), got '
                              f'{self.corner_quality!r}')
        if self.orb_max_hamming > ORB_DESCRIPTOR_BITS:
            raise ConfigError(f'{owner}.orb_max_hamming: must be <= {ORB_DESCRIPTOR_BITS} '
                              f'(bits in an ORB descriptor), got {self.orb_max_hamming}')
        if not self.min_depth_m < self.max_depth_m:
            raise ConfigError(f'{owner}.max_depth_m: must be above min_depth_m '
                              f'({self.min_depth_m}), got {self.max_depth_m}')


@dataclass(frozen=True)
class CorrectionConfig:
    """Feeding refined poses back to the live stream.

    Attributes:
        blend_s: live frames move from the previous correction to a new BA result over this
            much frame time instead of jumping (s); 0 applies a result at once.

    """

    blend_s: float = 0.3

    def __post_init__(self) -> None:
        require_finite('ba.corrections', blend_s=self.blend_s)
        require_at_least('ba.corrections', 0, blend_s=self.blend_s)


@dataclass(frozen=True)
class EpisodeConfig:
    """One refinement of the whole episode after an offline stream ends (``ba.episode``).

    Attributes:
        enabled: refine the episode as a whole when the stream settles (offline runs); the
            keyframes are kept for it.
        max_keyframes: keyframes kept for it, spread over the episode: past this many every
            other one is dropped and only every other later one kept (bounded memory and time).
        min_gain: it is used only where it lowers the held-out cost by at least this share of
            the start's, in [0, 1) ...
        min_z: ... and by at least this many standard errors of that decrease (over the
            held-out tracks): a gain the images show, not noise.
        max_move_share: and no keyframe moves further than this share of the episode's path
            (or than the images can see at all, ``ba.episode``).
        irls_iterations: most Huber (IRLS) iterations of its solve (``ba.solver``'s other
            settings hold): solved once, offline, it may run to convergence.

    """

    enabled: bool = False
    max_keyframes: int = 64
    min_gain: float = 0.05
    min_z: float = 3.0
    max_move_share: float = 0.25
    irls_iterations: int = 12

    def __post_init__(self) -> None:
        owner = 'ba.episode'
        _require_finite_fields(owner, self)
        require_at_least(owner, 2, max_keyframes=self.max_keyframes)
        require_at_least(owner, 0, irls_iterations=self.irls_iterations)
        require_at_least(owner, 0.0, min_z=self.min_z, max_move_share=self.max_move_share)
        if not 0.0 <= self.min_gain < 1.0:
            raise ConfigError(f'{owner}.min_gain: must be in [0, 1), got {self.min_gain!r}')


@dataclass(frozen=True)
class WorkerConfig:
    """How the background BA process shares the machine with the stream.

    Attributes:
        niceness: CPU niceness of the BA process (0..19); 19 keeps the stream's latency but lets
            BA fall behind on a saturated CPU, 0 shares the CPU evenly (offline conversion).
        max_queued_selections: pool selections allowed to wait for the BA process.
        when_behind: what a new selection does when that many already wait: ``drop`` the
            oldest waiting one (live streams: the newest poses get refined, the stream never
            waits) or ``wait`` for room (offline runs: every selection is refined; the stream
            waits for BA).

    """

    niceness: int = 19
    max_queued_selections: int = 2
    when_behind: str = 'drop'

    def __post_init__(self) -> None:
        if not 0 <= self.niceness <= MAX_NICENESS:
            raise ConfigError(f'ba.worker.niceness: must be in 0..{MAX_NICENESS}, got '
                              f'{self.niceness}')
        require_at_least('ba.worker', 1, max_queued_selections=self.max_queued_selections)
        if self.when_behind not in WHEN_BEHIND:
            raise ConfigError(f'ba.worker.when_behind: must be one of {", ".join(WHEN_BEHIND)}, '
                              f'got {self.when_behind!r}')


@dataclass(frozen=True)
class BAConfig:
    """All bundle-adjustment settings (``config/ba.yaml``, section ``ba``).

    Attributes:
        pool: the binary keyframe pool (which keyframes enter and are selected).
        solver: the sparse solver (robust loss, iterations, gauge).
        tracking: the feature tracks between the selected keyframes.
        corrections: how BA's poses are checked and folded back into the stream.
        worker: the background worker (queue length, what happens when it falls behind).
        episode: the whole-episode refinement when an offline stream ends.

    """

    pool: PoolConfig = field(default_factory=PoolConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    corrections: CorrectionConfig = field(default_factory=CorrectionConfig)
    worker: WorkerConfig = field(default_factory=WorkerConfig)
    episode: EpisodeConfig = field(default_factory=EpisodeConfig)


def load_ba_config(path: str | Path | None = None) -> BAConfig:
    """Load the ``ba`` section of ``path`` (default: the package's ``config/ba.yaml``)."""
    return load_config(config_dir() / 'ba.yaml' if path is None else path, BA_SECTION,
                       BAConfig)
