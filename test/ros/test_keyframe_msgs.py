"""Keyframe and correction messages between the nodes (ros/bundle_adjustment/keyframe_msgs.py)."""

from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
import numpy as np
import pytest

pytest.importorskip('rclpy', reason='rclpy is not importable (source scripts/env.sh)')
keyframe_msgs = pytest.importorskip('infinihand_ros.ros.bundle_adjustment.keyframe_msgs')

pytestmark = pytest.mark.ros
INTRINSICS = Intrinsics(300.0, 310.0, 20.5, 15.5, 40, 30)


def _keyframe(rng: np.random.Generator) -> KeyframeInput:
    pose = np.eye(4)
    pose[:3, :3] = geometry.axis_angle_to_matrix(np.array([0.1, -0.2, 0.3]))
    pose[:3, 3] = [0.5, -1.0, 2.0]
    depth = rng.uniform(0.5, 3.0, (30, 40)).astype(np.float32)
    depth[0, 0] = np.nan
    mask = np.zeros((30, 40), bool)
    mask[5:10, 20:30] = True
    return KeyframeInput(7, 1_234_567_890_123, rng.integers(0, 255, (30, 40, 3), np.uint8),
                         depth, pose, INTRINSICS, mask)


def test_keyframe_round_trip(rng: np.random.Generator) -> None:
    """Five messages with one stamp decode to the same image, depth, mask, pose, intrinsics."""
    sent = _keyframe(rng)
    msgs = keyframe_msgs.keyframe_msgs(sent, 'world', 'cam_optical')
    assert set(msgs) == set(keyframe_msgs.KEYFRAME_PARTS)
    assert msgs['depth'].encoding == '32FC1' and msgs['hand_mask'].encoding == 'mono8'
    got = keyframe_msgs.keyframe_from_msgs(msgs, 3)
    assert got.frame_id == 3 and got.timestamp_ns == sent.timestamp_ns
    np.testing.assert_array_equal(got.image, sent.image)
    np.testing.assert_array_equal(got.depth, sent.depth)  # NaN where unknown, too
    np.testing.assert_array_equal(got.hand_mask, sent.hand_mask)
    np.testing.assert_allclose(got.T_world_cam, sent.T_world_cam, atol=1e-12)
    np.testing.assert_allclose(got.intrinsics.matrix(), INTRINSICS.matrix())


def test_bad_keyframes_are_refused(rng: np.random.Generator) -> None:
    """A missing part, mixed stamps or a wrong depth encoding raise InputError naming it."""
    msgs = keyframe_msgs.keyframe_msgs(_keyframe(rng), 'world', 'cam')
    with pytest.raises(InputError, match='pose'):
        keyframe_msgs.keyframe_from_msgs({k: v for k, v in msgs.items() if k != 'pose'}, 0)
    msgs['pose'].header.stamp.sec += 1
    with pytest.raises(InputError, match='different stamps'):
        keyframe_msgs.keyframe_from_msgs(msgs, 0)
    msgs = keyframe_msgs.keyframe_msgs(_keyframe(rng), 'world', 'cam')
    msgs['depth'].encoding = '16UC1'
    with pytest.raises(InputError, match='32FC1'):
        keyframe_msgs.keyframe_from_msgs(msgs, 0)


def test_corrections_round_trip_and_checks() -> None:
    """Stamps and rigid corrections survive the Path; an empty path is refused."""
    correction = np.eye(4)
    correction[:3, :3] = geometry.axis_angle_to_matrix(np.array([0.0, 0.05, 0.0]))
    correction[:3, 3] = [0.01, 0.0, -0.02]
    sent = keyframe_msgs.Corrections(np.array([5, 9], dtype=np.int64),
                                     np.stack([np.eye(4), correction]))
    msg = keyframe_msgs.corrections_msg(9, 'world', sent)
    got = keyframe_msgs.corrections_from_msg(msg)
    np.testing.assert_array_equal(got.times_ns, [5, 9])
    np.testing.assert_allclose(got.corrections, sent.corrections, atol=1e-12)
    msg.poses = []
    with pytest.raises(InputError, match='empty'):
        keyframe_msgs.corrections_from_msg(msg)
