"""Sparse bundle adjustment beside the stream (paper Sec. 3.3): pool in, corrections out.

Each keyframe (image, metric depth, its metrically scaled pose, hand boxes) enters the binary
keyframe pool; when the pool triggers, its selection goes to a ``BundleAdjustmentWorker``
(BA runs in its own process, so its thread settings, CPU priority and crashes stay there) and
the stream goes on at once. Finished BA calls are handed to the pose track
(``engine/pose_track.py``), which applies them as corrections; nothing here places hands or
changes results. The track's correction history is pruned to what the pool and the track can
still query, so memory and time stay bounded on an unbounded stream.
"""

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.keyframe_pool import BinaryKeyframePool
from infinihand_ros.ba.worker import BundleAdjustmentWorker
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.engine.camera_space import CameraSpaceFrame
from infinihand_ros.engine.pose_track import PoseTrack
import numpy as np


def hand_mask_from_boxes(hands: tuple[HandState, ...], intrinsics: Intrinsics) -> np.ndarray:
    """Return an (H, W) bool mask covering the hands' boxes (kept out of tracking)."""
    mask = np.zeros((intrinsics.height, intrinsics.width), dtype=bool)
    for hand in hands:
        x0, y0 = np.floor(np.clip(hand.box_xyxy[:2], 0, None)).astype(int)
        x1, y1 = np.ceil(hand.box_xyxy[2:]).astype(int)
        mask[y0:max(y1, y0), x0:max(x1, x0)] = True
    return mask


class BundleAdjustmentStage:
    """Keyframes into the pool, BA in a background worker, results to the pose track."""

    def __init__(self, config: BAConfig) -> None:
        """Start the BA worker with an empty pool."""
        self.config = config
        self.pool = BinaryKeyframePool(config.pool.trigger, config.pool.stride)
        self.worker = BundleAdjustmentWorker(config)
        self.calls_submitted = 0
        self.calls_done = 0

    def fold_in(self, track: PoseTrack) -> None:
        """Hand finished BA calls to ``track``; prune corrections nobody can query any more."""
        for output in self.worker.poll():
            track.update_corrections(output.timestamps_ns, output.T_world_cam_refined,
                                     output.T_world_cam_raw)
            self.calls_done += 1
        stamps = [entry.state.timestamp_ns for entry in self.pool.entries()]
        oldest = track.oldest_timestamp_ns
        if oldest is not None:
            track.corrections.prune(min([oldest, *stamps]))

    def settle(self, track: PoseTrack, timeout_s: float | None = None) -> bool:
        """Wait for every queued BA call, then hand the results to ``track``.

        Returns:
            True when BA finished everything it was given, False when ``timeout_s`` ran out.

        """
        idle = self.worker.wait_idle(timeout_s)
        self.fold_in(track)
        return idle

    def offer(self, record: CameraSpaceFrame, pose: CameraPose, depth_m: np.ndarray | None
              ) -> None:
        """Feed a keyframe (with its scaled pose and metric depth) to the pool; never waits."""
        frame = record.frame
        if not frame.keyframe or depth_m is None or frame.source_image is None:
            return
        keyframe = KeyframeInput(frame.index, frame.timestamp_ns, frame.source_image, depth_m,
                                 pose.matrix(), record.intrinsics,
                                 hand_mask_from_boxes(record.hands, record.intrinsics))
        if self.pool.push(frame.index, keyframe) is not None:
            self.worker.submit_selection([entry.state for entry in self.pool.last_selection],
                                         self.pool.frame_ids())
            self.calls_submitted += 1

    def statistics(self) -> dict[str, object]:
        """Return the BA worker's state, its counters and last error, and the results folded in.

        ``state`` is 'idle', 'running', 'stopped' or 'failed' (the BA process kept dying;
        the stream goes on with unrefined poses).
        """
        worker = self.worker.statistics
        return {'state': str(worker.state), 'submitted': worker.submitted, 'done': worker.done,
                'dropped': worker.dropped, 'failed': worker.failed,
                'callback_errors': worker.callback_errors, 'last_error': worker.last_error,
                'folded_in': self.calls_done}

    def close(self) -> None:
        """Finish queued BA calls and stop the worker."""
        self.worker.close()
