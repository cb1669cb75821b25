"""The one authority for camera poses: tracked raw poses, the metric scale and BA corrections.

Per frame the track keeps a raw camera-to-world pose (model units). The network's pose is
re-anchored so that the world is exactly the first frame's camera (the project's convention and
the paper's eq. 9): ``T_net(0)^-1 T_net(t)``, so the first pose is the identity even when the
camera head's prediction for the first anchor is not quite; the per-frame tracker
(``engine/camera_tracker.py``, the track's front end) then measures the pose from the image,
with that network pose as its prior and fallback, giving ``T_raw``. The
best pose of a frame is ``S(s) [D(t) @ T_raw]``: ``S(s)`` scales the translation by the
trajectory's metric scale ``s`` (metres per model unit; one value for the whole track, so every
frame is rescaled together, never frame by frame) and ``D(t)`` is the bundle-adjustment
correction of the frame's time (rigid, blended in for live frames, see ``ba/corrections.py``),
kept in model units so that it stays right when the scale moves after BA ran.

The scale starts at ``metric_scale.initial`` (model units). During the warm-up the estimator
collects hand/depth ratios; once it has ``min_samples`` the scale is set to the estimate in one
step. After that the applied scale follows the estimate smoothly: each frame it moves towards it
by at most ``max_scale_step`` (relative), and only when the estimate differs by more than
``scale_deadband``. Every change of the scale or of the BA corrections increments ``version``,
and every pose read from the track carries the version it was computed with. Memory is bounded:
the track remembers the newest ``capacity`` frames.
"""

from collections import OrderedDict
from dataclasses import dataclass
from typing import Final

from infinihand_ros.ba.corrections import CorrectionTrack
from infinihand_ros.ba.keyframe import rescaled
from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.geometry import invert_transform
from infinihand_ros.engine.camera_tracker import CameraTracker
from infinihand_ros.engine.camera_tracker import TrackerConfig
from infinihand_ros.engine.camera_tracker import TrackerMoment
from infinihand_ros.engine.camera_tracker import TrackingView
from infinihand_ros.engine.metric_scale import MetricScaleConfig
from infinihand_ros.engine.metric_scale import MetricScaleEstimator
from infinihand_ros.engine.metric_scale import ScaleEstimate
import numpy as np
from scipy.spatial.transform import Rotation

SCALE_STATES: Final = ('warmup', 'tracking')


@dataclass(frozen=True)
class PoseTrackConfig:
    """Settings of the pose track (section ``pose_track`` of the engine config).

    Attributes:
        capacity: frames remembered (newest first out of the track when it is full).
        max_scale_step: after the warm-up, the applied scale changes by at most this fraction
            per frame (0.01: at most 1 % per frame).
        scale_deadband: the applied scale is left alone while the estimate is within this
            fraction of it (no version change for noise).
        correction_blend_s: frame time over which live frames blend into a new BA correction
            that comes from outside the engine (the BA node); with the engine's own BA,
            ``bundle_adjustment.corrections.blend_s`` applies instead.

    """

    capacity: int = 1024
    max_scale_step: float = 0.01
    scale_deadband: float = 0.002
    correction_blend_s: float = 0.3

    def __post_init__(self) -> None:
        require_at_least('pose_track', 1, capacity=self.capacity)
        require_positive('pose_track', max_scale_step=self.max_scale_step)
        require_at_least('pose_track', 0.0, scale_deadband=self.scale_deadband,
                         correction_blend_s=self.correction_blend_s)
        if not self.scale_deadband < self.max_scale_step < 1.0:
            raise ConfigError(f'pose_track: need scale_deadband < max_scale_step < 1, got '
                              f'{self.scale_deadband} and {self.max_scale_step}')


@dataclass(frozen=True)
class TrackedPose:
    """A frame's best pose and what it was computed from.

    Attributes:
        camera_pose: best camera-to-world pose, metres (metric scale and BA applied).
        scaled_pose: the metrically scaled raw pose, before BA corrections.
        scale: metres per model unit used.
        version: the track's version when the pose was read.
        tracking: how the raw pose was found (``camera_tracker.TRACKING_STATES``).

    """

    camera_pose: CameraPose
    scaled_pose: CameraPose
    scale: float
    version: int
    tracking: str


@dataclass(frozen=True)
class _Entry:
    timestamp_ns: int
    T_raw: np.ndarray
    tracking: str


class PoseTrack:
    """Raw poses, one metric scale and BA corrections of one stream (not thread-safe)."""

    def __init__(self, config: PoseTrackConfig, scale_config: MetricScaleConfig,
                 blend_s: float = 0.0, tracker_config: TrackerConfig | None = None) -> None:
        """Start an empty track.

        Args:
            config: capacity and scale smoothing.
            scale_config: the running metric-scale estimate's settings.
            blend_s: frame time over which live frames blend into a new BA correction.
            tracker_config: the per-frame tracker's settings (None: the defaults).

        """
        self.config = config
        self.tracker = CameraTracker(tracker_config or TrackerConfig())
        self.estimator = MetricScaleEstimator(scale_config)
        self.corrections = CorrectionTrack(blend_s)
        self._entries: OrderedDict[int, _Entry] = OrderedDict()
        self._world_from_network: np.ndarray | None = None  # T_net(0)^-1, set by the first add
        self._scale = scale_config.initial
        self._state = SCALE_STATES[0]
        self.version = 0

    @property
    def scale(self) -> float:
        """Return the applied metric scale, metres per model unit."""
        return self._scale

    @property
    def scale_state(self) -> str:
        """Return 'warmup' (scale not yet estimated) or 'tracking'."""
        return self._state

    @property
    def oldest_timestamp_ns(self) -> int | None:
        """Return the stamp of the oldest frame still in the track, or None when empty."""
        return next(iter(self._entries.values())).timestamp_ns if self._entries else None

    def scale_estimate(self) -> ScaleEstimate:
        """Return the estimator's current estimate (what the applied scale follows)."""
        return self.estimator.estimate()

    def add(self, frame_index: int, timestamp_ns: int, T_network: np.ndarray | None,
            view: TrackingView | None = None) -> str:
        """Record a frame: its network camera-to-world pose (4, 4, model units) and image.

        The tracker measures the frame's pose in ``view`` (without one, the network's motion
        is used). ``T_network`` is None for a frame the geometry branch skipped (tracked from
        the image alone). Returns how the pose was found (``camera_tracker.TRACKING_STATES``).
        """
        if T_network is not None:
            T_network = np.array(T_network, dtype=np.float64)
            if self._world_from_network is None:
                self._world_from_network = invert_transform(T_network)
            T_network = self._world_from_network @ T_network
        tracked = self.tracker.track(view, T_network)
        self._entries[frame_index] = _Entry(timestamp_ns, tracked.T_raw, tracked.state)
        while len(self._entries) > self.config.capacity:
            self._entries.popitem(last=False)
        return tracked.state

    def absorb(self, frame_index: int, T_network: np.ndarray, view: TrackingView,
               moment: TrackerMoment | None = None) -> None:
        """Take the network pose (4, 4) and view with depth of a frame added without.

        For a frame whose geometry ran after its answer went out (``CameraTracker.absorb``;
        ``moment``: the tracker right after that frame, when later frames were added since);
        a frame the tracker lost takes the network's motion in the track.
        """
        T_network = self._world_from_network @ np.array(T_network, dtype=np.float64)
        bridged = self.tracker.absorb(view, T_network, moment)
        entry = self._entries.get(frame_index)
        if bridged is not None and entry is not None:
            self._entries[frame_index] = _Entry(entry.timestamp_ns, bridged, entry.tracking)

    def observe_scale(self, metric_depths: np.ndarray, model_depths: np.ndarray) -> None:
        """Feed hand depths (m) and model depths at the same pixels; update the applied scale."""
        self.estimator.observe(metric_depths, model_depths)
        estimate = self.estimator.estimate()
        if estimate.samples < self.estimator.config.min_samples:
            return
        if self._state == 'warmup':
            self._state = SCALE_STATES[1]
            self._set_scale(estimate.scale)
            return
        ratio = estimate.scale / self._scale
        if abs(ratio - 1.0) <= self.config.scale_deadband:
            return
        step = self.config.max_scale_step
        self._set_scale(self._scale * float(np.clip(ratio, 1.0 / (1.0 + step), 1.0 + step)))

    def update_corrections(self, timestamps_ns: np.ndarray, T_refined: np.ndarray,
                           T_submitted: np.ndarray, scale: float | None = None) -> None:
        """Take a finished BA call: refined and submitted keyframe poses (K, 4, 4).

        Both are metric at ``scale`` (the call's; None: the track's scale now); they are kept
        in model units.
        """
        self.corrections.update(timestamps_ns, T_refined, T_submitted,
                                self._scale if scale is None else scale)
        self.version += 1

    def scaled(self, frame_index: int) -> CameraPose:
        """Return the frame's raw pose with the metric scale applied (BA's input pose).

        Raises:
            KeyError: for a frame that is not (or no longer) in the track.

        """
        transform = self._entries[frame_index].T_raw.copy()
        transform[:3, 3] *= self._scale
        return CameraPose.from_matrix(transform)

    def best(self, frame_index: int, live: bool = True) -> TrackedPose:
        """Return the frame's best pose; ``live`` blends new BA corrections in (no jumps).

        Raises:
            KeyError: for a frame that is not (or no longer) in the track.

        """
        entry = self._entries[frame_index]
        scaled = self.scaled(frame_index)
        if not len(self.corrections):
            return TrackedPose(scaled, scaled, self._scale, self.version, entry.tracking)
        raw = entry.T_raw
        corrected = rescaled(
            self.corrections.correct_live(entry.timestamp_ns, raw) if live
            else self.corrections.correct(np.array([entry.timestamp_ns]), raw[None])[0],
            self._scale)
        # Corrections are rigid; re-orthonormalise away the rounding of their interpolation.
        pose = CameraPose(Rotation.from_matrix(corrected[:3, :3]).as_matrix(), corrected[:3, 3])
        return TrackedPose(pose, scaled, self._scale, self.version, entry.tracking)

    def _set_scale(self, scale: float) -> None:
        self._scale = float(scale)
        self.version += 1
