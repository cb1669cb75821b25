"""The remote BA backend (engine/ba_remote.py) and the keyframe every backend gets."""

from infinihand_ros.ba.corrections import Corrections
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.engine.ba_backend import keyframe_input
from infinihand_ros.engine.ba_backend import moving_mask
from infinihand_ros.engine.ba_remote import RemoteBA
from infinihand_ros.engine.metric_scale import MetricScaleConfig
from infinihand_ros.engine.pose_track import PoseTrack
from infinihand_ros.engine.pose_track import PoseTrackConfig
import numpy as np
from result_builders import INTRINSICS
from result_builders import make_hand

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


def _keyframe(track: PoseTrack):
    image = np.zeros((INTRINSICS.height, INTRINSICS.width, 3), dtype=np.uint8)
    depth = np.full((INTRINSICS.height, INTRINSICS.width), 1.5, dtype=np.float32)
    return keyframe_input(1, STAMP, image, depth, track.scaled(1), INTRINSICS, (make_hand(0),))


def test_keyframe_carries_the_scaled_pose_depth_and_hand_boxes() -> None:
    """The pose is the raw pose at the track's scale; the mask covers the 50 px hand box.

    The rest of the mask is the forearm's wedge (``moving_mask``), beyond the box.
    """
    keyframe = _keyframe(_track())
    np.testing.assert_allclose(keyframe.T_world_cam[:3, 3], [2.0, 4.0, 6.0])
    assert keyframe.timestamp_ns == STAMP and keyframe.frame_id == 1
    assert keyframe.hand_mask[:50, :50].all()
    np.testing.assert_array_equal(keyframe.hand_mask, moving_mask((make_hand(0),), INTRINSICS))
    assert float(keyframe.depth[0, 0]) == 1.5


def test_offered_keyframes_wait_for_the_transport_bounded() -> None:
    """Keyframes come out once, oldest first; an absent transport keeps only the newest."""
    remote = RemoteBA(outbox_size=2)
    keyframe = _keyframe(_track())
    for _ in range(3):
        remote.offer(keyframe)
    assert len(remote.take_keyframes()) == 2
    assert remote.take_keyframes() == []
    assert remote.statistics()['offered'] == 3


def test_received_corrections_move_the_best_pose_and_bump_the_version() -> None:
    """A correction shifting x by 0.5 m moves the frame's best pose by that, version + 1."""
    track = _track()
    version = track.version
    correction = np.eye(4)
    correction[0, 3] = 0.5
    remote = RemoteBA()
    remote.receive(Corrections(np.array([STAMP]), correction[None]))
    assert track.best(1, live=False).version == version  # nothing until folded in
    remote.fold_in(track)
    best = track.best(1, live=False)
    np.testing.assert_allclose(best.camera_pose.translation, [2.5, 4.0, 6.0])
    np.testing.assert_allclose(best.scaled_pose.translation, [2.0, 4.0, 6.0])
    assert best.version == version + 1
    assert remote.statistics()['folded_in'] == 1
    remote.reset()
    assert remote.take_keyframes() == []
    assert isinstance(track.best(1).camera_pose, CameraPose)
