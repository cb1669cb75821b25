"""Plain-data inputs and outputs of a bundle-adjustment call (what the worker exchanges)."""

from dataclasses import dataclass

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

    """

    frame_id: int
    timestamp_ns: int
    image: np.ndarray
    depth: np.ndarray
    T_world_cam: np.ndarray
    intrinsics: Intrinsics
    hand_mask: np.ndarray

    def __post_init__(self) -> None:
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
