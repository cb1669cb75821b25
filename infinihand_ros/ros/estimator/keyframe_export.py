"""What the estimator hands to the bundle-adjustment node per keyframe, and what it takes back.

``keyframe_for_ba`` gives a keyframe exactly what the engine's in-process BA stage gives its
pool (``engine/ba_stage.py``): the source image, the metric depth, the metrically scaled raw
pose (before any correction, at the scale the result was made with) and the hand boxes as a
mask. ``apply_corrections`` feeds a BA node's corrections into the engine's pose track the way
the stage does: through ``PoseTrack.update_corrections``, then prunes what no frame still in
the track can query.
"""

from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.engine.ba_stage import hand_mask_from_boxes
from infinihand_ros.engine.pose_track import PoseTrack
import numpy as np


def keyframe_for_ba(result: FrameResult, image: np.ndarray, track: PoseTrack
                    ) -> KeyframeInput | None:
    """Return the BA input of a keyframe result, or None for other frames.

    Args:
        result: an engine result (its frame must still be in ``track``).
        image: (H, W, 3) uint8 RGB source image of the result.
        track: the engine's pose track.

    """
    if not result.is_keyframe or result.depth is None:
        return None
    pose = track.scaled(result.frame_index).matrix()
    # The track scales with its current scale; the result was made with its own.
    pose[:3, 3] *= result.metric_scale / track.scale
    return KeyframeInput(result.frame_index, result.timestamp_ns, image, result.depth, pose,
                         result.intrinsics, hand_mask_from_boxes(result.hands, result.intrinsics))


def apply_corrections(track: PoseTrack, times_ns: np.ndarray, corrections: np.ndarray) -> None:
    """Apply BA corrections (K, 4, 4) of keyframes stamped ``times_ns`` (K,) to ``track``.

    A correction ``D`` maps a keyframe's submitted (scaled raw) pose onto its refined one, so
    it is handed over as refined ``D`` over submitted identity.
    """
    identity = np.broadcast_to(np.eye(4), np.shape(corrections))
    track.update_corrections(np.asarray(times_ns), np.asarray(corrections), identity)
    oldest = track.oldest_timestamp_ns
    if oldest is not None:
        track.corrections.prune(oldest)
