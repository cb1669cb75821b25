"""Keyframes for the BA node, corrections into the pose track (estimator/keyframe_export.py)."""

from dataclasses import replace

from infinihand_ros.engine.metric_scale import MetricScaleConfig
from infinihand_ros.engine.pose_track import PoseTrack
from infinihand_ros.engine.pose_track import PoseTrackConfig
from infinihand_ros.ros.estimator.keyframe_export import apply_corrections
from infinihand_ros.ros.estimator.keyframe_export import keyframe_for_ba
import numpy as np
from ros_builders import INTRINSICS
from ros_builders import make_hand
from ros_builders import make_result

STAMP = 5_000_000_000
T_RAW = np.eye(4)
T_RAW[:3, 3] = [1.0, 2.0, 3.0]


def _track() -> PoseTrack:
    """Return a track holding frame 1 at T_RAW, its scale moved to 2.0 by five ratios."""
    track = PoseTrack(PoseTrackConfig(), MetricScaleConfig())
    track.add(0, STAMP - 1, np.eye(4))  # the first frame is the world
    track.add(1, STAMP, T_RAW)
    track.observe_scale(np.full(5, 2.0), np.ones(5))
    assert track.scale == 2.0
    return track


def _keyframe_result(metric_scale: float):
    depth = np.full((INTRINSICS.height, INTRINSICS.width), 1.5, dtype=np.float32)
    return replace(make_result(STAMP, (make_hand(0),), index=1), is_keyframe=True, depth=depth,
                   metric_scale=metric_scale)


def test_keyframe_carries_the_result_scale_pose_depth_and_hand_boxes() -> None:
    """The pose is the raw pose at the result's scale; the mask covers the 50 px hand box."""
    image = np.zeros((INTRINSICS.height, INTRINSICS.width, 3), dtype=np.uint8)
    track = _track()
    keyframe = keyframe_for_ba(_keyframe_result(1.0), image, track)
    np.testing.assert_allclose(keyframe.T_world_cam[:3, 3], [1.0, 2.0, 3.0])
    at_two = keyframe_for_ba(_keyframe_result(2.0), image, track)
    np.testing.assert_allclose(at_two.T_world_cam[:3, 3], [2.0, 4.0, 6.0])
    assert keyframe.timestamp_ns == STAMP and keyframe.frame_id == 1
    assert keyframe.hand_mask[:50, :50].all() and keyframe.hand_mask.sum() == 50 * 50
    assert float(keyframe.depth[0, 0]) == 1.5


def test_other_frames_are_not_exported() -> None:
    """A result that is no keyframe (or has no depth) gives None."""
    image = np.zeros((INTRINSICS.height, INTRINSICS.width, 3), dtype=np.uint8)
    result = replace(_keyframe_result(1.0), is_keyframe=False)
    assert keyframe_for_ba(result, image, _track()) is None


def test_corrections_move_the_best_pose_and_bump_the_version() -> None:
    """A correction shifting x by 0.5 m moves the frame's best pose by that, version + 1."""
    track = _track()
    version = track.version
    correction = np.eye(4)
    correction[0, 3] = 0.5
    apply_corrections(track, np.array([STAMP]), correction[None])
    best = track.best(1, live=False)
    np.testing.assert_allclose(best.camera_pose.translation, [2.5, 4.0, 6.0])
    np.testing.assert_allclose(best.scaled_pose.translation, [2.0, 4.0, 6.0])
    assert best.version == version + 1
