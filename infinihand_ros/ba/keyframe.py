"""Plain-data inputs and outputs of a bundle-adjustment call (what the worker exchanges).

Poses and depths are metric at the stream's metric scale when the keyframe was made
(``KeyframeInput.scale``, metres per model unit); that scale can move while the stream runs, so
a call brings its keyframes to one scale first (``KeyframeInput.at_scale``) and its output
says which (``BAOutput.scale``).
"""

from dataclasses import dataclass
from dataclasses import replace

from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.validation import as_array
import numpy as np


@dataclass(frozen=True)
class KeyframeInput:
    """One keyframe as the stream hands it to BA.

    Attributes:
        frame_id: the frame's index in the stream.
        timestamp_ns: the source image's stamp (ns).
        image: (H, W, 3) uint8 RGB image.
        depth: (H, W) float32 depth along the optical axis from the model (m); non-finite or
            non-positive where unknown.
        T_world_cam: (4, 4) raw camera-to-world pose from the estimator (m).
        intrinsics: pinhole intrinsics of the image.
        hand_mask: (H, W) bool, True on hands (and arms) of either side: excluded from tracking.
        scale: the metric scale (metres per model unit) the pose and depth were scaled with.
        calibrated: the intrinsics were given (CameraInfo, ``--intrinsics``), not predicted:
            BA holds the lens.

    """

    frame_id: int
    timestamp_ns: int
    image: np.ndarray
    depth: np.ndarray
    T_world_cam: np.ndarray
    intrinsics: Intrinsics
    hand_mask: np.ndarray
    scale: float = 1.0
    calibrated: bool = False

    def __post_init__(self) -> None:
        if not (np.isfinite(self.scale) and self.scale > 0):
            raise InputError(f'keyframe {self.frame_id}: scale must be positive and finite, '
                             f'got {self.scale!r}')
        height, width = self.intrinsics.height, self.intrinsics.width
        image = np.asarray(self.image)
        if image.shape != (height, width, 3) or image.dtype != np.uint8:
            raise InputError(f'keyframe {self.frame_id}: image must be ({height}, {width}, 3) '
                             f'uint8 RGB like its intrinsics, got {image.shape} {image.dtype}')
        object.__setattr__(self, 'depth', as_array(self.depth, f'keyframe {self.frame_id} depth',
                                                   (height, width), np.float32, finite=False))
        object.__setattr__(self, 'hand_mask', as_array(
            self.hand_mask, f'keyframe {self.frame_id} hand_mask', (height, width), bool))
        object.__setattr__(self, 'T_world_cam', as_array(
            self.T_world_cam, f'keyframe {self.frame_id} T_world_cam', (4, 4)))

    def at_scale(self, scale: float) -> 'KeyframeInput':
        """Return the keyframe with its pose's translation and its depth at metric ``scale``."""
        if scale == self.scale:
            return self
        factor = scale / self.scale
        return replace(self, T_world_cam=rescaled(self.T_world_cam, factor),
                       depth=self.depth * np.float32(factor), scale=float(scale))


@dataclass(frozen=True)
class StreamLens:
    """The stream's lens as the BA calls so far found it (one camera, one lens).

    Attributes:
        focal_px: focal length (px) at the keyframes' image size.
        k1: radial distortion coefficient (``ba.costs``).
        calls: accepted calls it averages.

    """

    focal_px: float
    k1: float
    calls: int

    def updated(self, focal_px: float, k1: float) -> 'StreamLens':
        """Return the average with one more call's lens."""
        count = self.calls + 1
        return StreamLens(self.focal_px + (focal_px - self.focal_px) / count,
                          self.k1 + (k1 - self.k1) / count, count)


def rescaled(T_world_cam: np.ndarray, factor: float) -> np.ndarray:
    """Return poses (..., 4, 4) with their translations multiplied by ``factor``."""
    out = np.array(T_world_cam, dtype=np.float64)
    out[..., :3, 3] *= factor
    return out


@dataclass(frozen=True)
class BAOutput:
    """Result of one BA call over a keyframe selection.

    Attributes:
        frame_ids: (K,) keyframes refined, time order.
        timestamps_ns: (K,) their stamps (ns).
        T_world_cam_raw: (K, 4, 4) the estimator's raw poses.
        T_world_cam_refined: (K, 4, 4) refined poses.
        num_tracks: tracks in the problem.
        num_observations: observations in the problem.
        num_inliers: observations kept by the outlier gate.
        seconds: wall time of the call (correspondences + solve).
        cpu_seconds: CPU time of the calling thread during the call (what the call itself cost,
            whatever else the machine runs).
        accepted: the refinement passed its held-out check (``ba.validation``); when it did
            not, ``T_world_cam_refined`` are the poses the call started from.
        held_out_costs: Huber cost per held-out observation (start, refined), px^2; NaN
            without a check.
        focal_px: the refined shared focal length of the first keyframe (px).
        k1: the refined shared radial distortion coefficient.
        scale: the metric scale of every pose here (the newest keyframe's; see the module).

    """

    frame_ids: np.ndarray
    timestamps_ns: np.ndarray
    T_world_cam_raw: np.ndarray
    T_world_cam_refined: np.ndarray
    num_tracks: int
    num_observations: int
    num_inliers: int
    seconds: float
    cpu_seconds: float
    accepted: bool = True
    held_out_costs: tuple[float, float] = (float('nan'), float('nan'))
    focal_px: float = float('nan')
    k1: float = 0.0
    scale: float = 1.0
