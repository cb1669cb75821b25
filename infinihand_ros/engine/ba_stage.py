"""Sparse bundle adjustment beside the stream (paper Sec. 3.3): pool, background BA, corrections.

Each keyframe result (with its image and depth) enters the binary keyframe pool; when the pool
triggers, its selection goes to a ``BundleAdjustmentWorker`` thread and the stream goes on at
once. Finished BA calls update the correction track; every result leaving the engine gets the
live correction (blended in, see ``ba/corrections.py``) applied to its camera pose and
world-space hands, and keeps its raw pose in ``raw_camera_pose``.
"""

from dataclasses import replace

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.corrections import CorrectionTrack
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.keyframe_pool import BinaryKeyframePool
from infinihand_ros.ba.worker import BundleAdjustmentWorker
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.engine.decode import place_in_world
import numpy as np
from scipy.spatial.transform import Rotation


def hand_mask_from_boxes(result: FrameResult) -> np.ndarray:
    """Return an (H, W) bool mask covering the result's hand boxes (kept out of tracking)."""
    mask = np.zeros((result.intrinsics.height, result.intrinsics.width), dtype=bool)
    for hand in result.hands:
        x0, y0 = np.floor(np.clip(hand.box_xyxy[:2], 0, None)).astype(int)
        x1, y1 = np.ceil(hand.box_xyxy[2:]).astype(int)
        mask[y0:max(y1, y0), x0:max(x1, x0)] = True
    return mask


class BundleAdjustmentStage:
    """Keyframes into the pool, BA in a background thread, live corrections onto results."""

    def __init__(self, config: BAConfig) -> None:
        """Start the BA worker thread with an empty pool and no corrections."""
        self.config = config
        self.pool = BinaryKeyframePool(config.pool.trigger, config.pool.stride)
        self.corrections = CorrectionTrack(config.corrections.blend_s)
        self.worker = BundleAdjustmentWorker(config)
        self.calls_submitted = 0
        self.calls_done = 0

    def apply(self, result: FrameResult, image: np.ndarray | None) -> FrameResult:
        """Feed a result (and, for keyframes, its source RGB image) to BA; return it corrected.

        Never waits for BA: finished calls are folded in, a triggered selection is queued.
        """
        for output in self.worker.poll():
            self.corrections.update(output.timestamps_ns, output.T_world_cam_refined,
                                    output.T_world_cam_raw)
            self.calls_done += 1
        raw = result.camera_pose
        if result.is_keyframe and result.depth is not None and image is not None:
            keyframe = KeyframeInput(result.frame_index, result.timestamp_ns, image, result.depth,
                                     raw.matrix(), result.intrinsics,
                                     hand_mask_from_boxes(result))
            if self.pool.push(result.frame_index, keyframe) is not None:
                self.worker.submit_selection([entry.state for entry in self.pool.last_selection],
                                             self.pool.frame_ids())
                self.calls_submitted += 1
        corrected = self.corrections.correct_live(result.timestamp_ns, raw.matrix())
        # Corrections are rigid; re-orthonormalise away the rounding of their interpolation.
        pose = CameraPose(Rotation.from_matrix(corrected[:3, :3]).as_matrix(), corrected[:3, 3])
        return replace(result, camera_pose=pose, raw_camera_pose=raw,
                       hands=tuple(place_in_world(hand, pose) for hand in result.hands))

    def close(self) -> None:
        """Finish queued BA calls and stop the worker thread."""
        self.worker.close()
