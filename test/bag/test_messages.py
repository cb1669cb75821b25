"""Tests of infinihand_ros/bag/messages.py: core dataclasses <-> messages, in memory and bags."""

from collections.abc import Callable
import dataclasses
from pathlib import Path
import shutil

from bag_builders import assert_frame_equal
from bag_builders import assert_keyframes_equal
from bag_builders import assert_pose_close
from bag_builders import BASE_STAMP_NS
from bag_builders import random_pose
from infinihand_ros.bag.messages import frame_result_to_msg
from infinihand_ros.bag.messages import hand_to_msg
from infinihand_ros.bag.messages import keyframe_poses_to_msg
from infinihand_ros.bag.messages import KeyframePoseUpdate
from infinihand_ros.bag.messages import msg_to_frame_result
from infinihand_ros.bag.messages import msg_to_hand
from infinihand_ros.bag.messages import msg_to_keyframe_poses
from infinihand_ros.bag.messages import msg_to_pose
from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.bag.messages import pose_to_msg
from infinihand_ros.bag.messages import stamp_from_ns
from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.bag.typestore import HAND_FRAME_MSG
from infinihand_ros.bag.typestore import HAND_MSG
from infinihand_ros.bag.typestore import IMAGE_MSG
from infinihand_ros.bag.typestore import KEYFRAME_POSES_MSG
from infinihand_ros.bag.typestore import msg_schema_dir
from infinihand_ros.bag.typestore import POSE_STAMPED_MSG
from infinihand_ros.core import geometry
from infinihand_ros.core import topics
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.output_fields import hand_output
from infinihand_ros.core.units import NS_PER_S
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer
from rosbags.typesys import get_typestore
from rosbags.typesys import Stores
from rosbags.typesys.store import Typestore

WORLD_FRAME = topics.WORLD_FRAME_ID
IMAGE_TOPIC = topics.IMAGE_TOPIC
FRAMES_TOPIC = '/infinihand_estimator/hand_frames'
KEYFRAMES_TOPIC = '/infinihand_estimator/keyframe_poses'
IMAGE_SHAPE = (6, 8, 3)

MakeFrame = Callable[..., FrameResult]


@pytest.mark.parametrize('timestamp_ns', [0, 1, BASE_STAMP_NS, -1, -3 * NS_PER_S // 2])
def test_stamp_round_trip(typestore: Typestore, timestamp_ns: int) -> None:
    stamp = stamp_from_ns(typestore, timestamp_ns)
    assert 0 <= stamp.nanosec < NS_PER_S
    assert stamp.sec * NS_PER_S + stamp.nanosec == timestamp_ns
    assert ns_from_stamp(stamp) == timestamp_ns


def test_stamp_outside_int32_seconds_raises(typestore: Typestore) -> None:
    with pytest.raises(InputError, match='outside the int32 seconds range'):
        stamp_from_ns(typestore, 2 ** 31 * NS_PER_S)


def test_pose_round_trip(typestore: Typestore, rng: np.random.Generator) -> None:
    pose = random_pose(rng)
    msg = pose_to_msg(typestore, pose)
    orientation = msg.orientation
    np.testing.assert_array_equal(
        [orientation.x, orientation.y, orientation.z, orientation.w], pose.quaternion_xyzw())
    assert (msg.position.x, msg.position.y, msg.position.z) == tuple(pose.translation)
    assert_pose_close(msg_to_pose(msg), pose)


def test_zero_quaternion_pose_raises(typestore: Typestore, rng: np.random.Generator) -> None:
    msg = pose_to_msg(typestore, random_pose(rng))
    msg.orientation.x = msg.orientation.y = msg.orientation.z = msg.orientation.w = 0.0
    with pytest.raises(InputError, match='zero quaternion'):
        msg_to_pose(msg)


def test_frame_round_trip_in_memory(typestore: Typestore, make_frame: MakeFrame) -> None:
    frame = make_frame()
    msg = frame_result_to_msg(typestore, frame, WORLD_FRAME)
    assert msg.header.frame_id == WORLD_FRAME
    assert ns_from_stamp(msg.header.stamp) == frame.timestamp_ns
    np.testing.assert_array_equal(msg.k, frame.intrinsics.matrix().reshape(-1))
    assert [hand.has_world for hand in msg.hands] == [True, False]
    assert_frame_equal(msg_to_frame_result(msg), frame)


def test_frame_round_trip_through_cdr(typestore: Typestore, make_frame: MakeFrame) -> None:
    frame = make_frame()
    raw = typestore.serialize_cdr(frame_result_to_msg(typestore, frame, WORLD_FRAME),
                                  HAND_FRAME_MSG)
    assert_frame_equal(msg_to_frame_result(typestore.deserialize_cdr(raw, HAND_FRAME_MSG)), frame)


def test_frame_without_hands_round_trips(typestore: Typestore, make_frame: MakeFrame) -> None:
    frame = dataclasses.replace(make_frame(), hands=())
    raw = typestore.serialize_cdr(frame_result_to_msg(typestore, frame, WORLD_FRAME),
                                  HAND_FRAME_MSG)
    decoded = msg_to_frame_result(typestore.deserialize_cdr(raw, HAND_FRAME_MSG))
    assert decoded.hands == ()
    assert_frame_equal(decoded, frame)


def test_wrist_pose_is_wrist_joint_with_global_orientation(
        typestore: Typestore, make_frame: MakeFrame) -> None:
    hand = make_frame().hand(LEFT)
    pose = msg_to_pose(hand_to_msg(typestore, hand).wrist_pose_world)
    np.testing.assert_array_equal(pose.translation, hand.joints_world[0])
    np.testing.assert_allclose(
        pose.rotation, geometry.axis_angle_to_matrix(hand.mano_world.global_orient), atol=1e-12)


def test_wrist_frame_fields_are_the_estimators_wrist_outputs(
        typestore: Typestore, make_frame: MakeFrame) -> None:
    """The wrist frame (the node's /tf wrist pose) and the joints in it, as the node publishes."""
    hand = make_frame().hand(LEFT)
    output = hand_output(hand)
    msg = hand_to_msg(typestore, hand)
    assert msg.has_wrist_frame
    pose = msg_to_pose(msg.wrist_frame_world)
    np.testing.assert_array_equal(pose.translation, output.wrist_pose.position)
    np.testing.assert_allclose(pose.quaternion_xyzw(), output.wrist_pose.orientation_xyzw,
                               atol=1e-12)
    joints = np.array([[p.x, p.y, p.z] for p in msg.joints_wrist])
    np.testing.assert_array_equal(joints, output.wrist_frame_landmarks)
    # Back in the world frame through the wrist frame's pose: the world joints.
    np.testing.assert_allclose(joints @ pose.rotation.T + pose.translation, hand.joints_world,
                               atol=1e-12)
    degenerate = dataclasses.replace(hand, joints_world=np.zeros_like(hand.joints_world))
    msg = hand_to_msg(typestore, degenerate)
    assert not msg.has_wrist_frame
    assert all((p.x, p.y, p.z) == (0.0, 0.0, 0.0) for p in msg.joints_wrist)


def test_hand_without_world_fields_is_zero_with_identity_wrist(
        typestore: Typestore, make_frame: MakeFrame) -> None:
    msg = hand_to_msg(typestore, make_frame().hand(RIGHT))
    assert not msg.has_world
    assert msg.side == typestore.types[HAND_MSG].RIGHT
    assert all((p.x, p.y, p.z) == (0.0, 0.0, 0.0) for p in msg.joints_world)
    assert not np.any(msg.mano_world.betas)
    np.testing.assert_array_equal(msg_to_pose(msg.wrist_pose_world).matrix(), np.eye(4))
    assert not msg.has_wrist_frame
    np.testing.assert_array_equal(msg_to_pose(msg.wrist_frame_world).matrix(), np.eye(4))
    decoded = msg_to_hand(msg)
    assert decoded.mano_world is None and decoded.joints_world is None


def test_keyframe_poses_round_trip(typestore: Typestore, make_keyframes: Callable) -> None:
    update = make_keyframes(4)
    msg = keyframe_poses_to_msg(typestore, update, WORLD_FRAME)
    assert ns_from_stamp(msg.header.stamp) == max(update.stamps_ns)
    assert msg.frame_indices.dtype == np.uint32
    raw = typestore.serialize_cdr(msg, KEYFRAME_POSES_MSG)
    decoded = msg_to_keyframe_poses(typestore.deserialize_cdr(raw, KEYFRAME_POSES_MSG))
    assert_keyframes_equal(decoded, update)
    explicit = keyframe_poses_to_msg(typestore, update, WORLD_FRAME, stamp_ns=BASE_STAMP_NS)
    assert ns_from_stamp(explicit.header.stamp) == BASE_STAMP_NS


def _image_msg(typestore: Typestore, stamp_ns: int, pixels: np.ndarray) -> object:
    """Build an rgb8 sensor_msgs/msg/Image."""
    header = typestore.types['std_msgs/msg/Header'](
        stamp=stamp_from_ns(typestore, stamp_ns), frame_id=topics.CAMERA_FRAME_ID)
    height, width, channels = pixels.shape
    return typestore.types[IMAGE_MSG](
        header=header, height=height, width=width, encoding='rgb8', is_bigendian=0,
        step=width * channels, data=pixels.reshape(-1))


def _write_bag(path: Path, typestore: Typestore, entries: list[tuple[str, str, object]]) -> None:
    """Write (topic, type, message) entries to a rosbag2 MCAP bag, stamped by their headers."""
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {}
        for topic, msgtype, msg in entries:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=typestore)
            writer.write(connections[topic], ns_from_stamp(msg.header.stamp),
                         typestore.serialize_cdr(msg, msgtype))


def test_mcap_bag_round_trip_without_a_typestore_on_read(
        tmp_path: Path, typestore: Typestore, make_frame: MakeFrame,
        make_keyframes: Callable, rng: np.random.Generator) -> None:
    frames = [make_frame(index) for index in range(3)]
    update = make_keyframes(2)
    images = [rng.integers(0, 256, size=IMAGE_SHAPE, dtype=np.uint8) for _ in frames]
    entries = [(FRAMES_TOPIC, HAND_FRAME_MSG, frame_result_to_msg(typestore, f, WORLD_FRAME))
               for f in frames]
    entries += [(IMAGE_TOPIC, IMAGE_MSG, _image_msg(typestore, f.timestamp_ns, image))
                for f, image in zip(frames, images)]
    entries.append((KEYFRAMES_TOPIC, KEYFRAME_POSES_MSG,
                    keyframe_poses_to_msg(typestore, update, WORLD_FRAME)))
    bag_path = tmp_path / 'bag'
    _write_bag(bag_path, typestore, entries)
    assert len(list(bag_path.glob('*.mcap'))) == 1

    decoded: dict[str, list[object]] = {FRAMES_TOPIC: [], IMAGE_TOPIC: [], KEYFRAMES_TOPIC: []}
    with AnyReader([bag_path]) as reader:  # types come from the definitions stored in the bag
        assert {c.topic: c.msgtype for c in reader.connections} == {
            FRAMES_TOPIC: HAND_FRAME_MSG, IMAGE_TOPIC: IMAGE_MSG,
            KEYFRAMES_TOPIC: KEYFRAME_POSES_MSG}
        for msgtype in (HAND_FRAME_MSG, KEYFRAME_POSES_MSG):
            assert reader.typestore.hash_rihs01(msgtype) == typestore.hash_rihs01(msgtype)
        for connection, timestamp, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            assert timestamp == ns_from_stamp(msg.header.stamp)
            decoded[connection.topic].append(msg)
    for msg, frame in zip(decoded[FRAMES_TOPIC], frames, strict=True):
        assert_frame_equal(msg_to_frame_result(msg), frame)
    for msg, image in zip(decoded[IMAGE_TOPIC], images, strict=True):
        np.testing.assert_array_equal(msg.data.reshape(msg.height, msg.width, 3), image)
    (keyframes_msg,) = decoded[KEYFRAMES_TOPIC]
    assert_keyframes_equal(msg_to_keyframe_poses(keyframes_msg), update)


def test_a_hand_frame_of_the_earlier_definition_reads_with_default_flags(
        tmp_path: Path, typestore: Typestore, make_frame: MakeFrame) -> None:
    """A HandFrame recorded before ``intrinsics_provisional`` and ``tracking``: their defaults."""
    schemas = tmp_path / 'msg'
    shutil.copytree(msg_schema_dir(), schemas)
    hand_frame = schemas / 'HandFrame.msg'
    hand_frame.write_text('\n'.join(
        line for line in hand_frame.read_text().splitlines()
        if line not in ('bool intrinsics_provisional', 'string tracking')) + '\n')
    earlier = build_typestore(schemas)
    assert earlier.hash_rihs01(HAND_FRAME_MSG) != typestore.hash_rihs01(HAND_FRAME_MSG)
    frame = make_frame(3)  # provisional lens, tracking 'reinitialised'
    current = frame_result_to_msg(typestore, frame, WORLD_FRAME)
    fields = {name: getattr(current, name) for name in current.__dataclass_fields__
              if name not in ('intrinsics_provisional', 'tracking')}
    msg_class = earlier.types[HAND_FRAME_MSG]
    raw = earlier.serialize_cdr(msg_class(**fields), HAND_FRAME_MSG)
    decoded = msg_to_frame_result(earlier.deserialize_cdr(raw, HAND_FRAME_MSG))
    assert (decoded.tracking, decoded.provisional_intrinsics) == ('predicted', False)
    assert_frame_equal(decoded, dataclasses.replace(frame, tracking='predicted',
                                                    provisional_intrinsics=False))


def test_hand_with_only_one_world_field_raises(
        typestore: Typestore, make_frame: MakeFrame) -> None:
    hand = dataclasses.replace(make_frame().hand(LEFT), joints_world=None)
    with pytest.raises(InputError, match='mano_world is set but joints_world is None'):
        hand_to_msg(typestore, hand)


def test_wrong_message_type_raises(typestore: Typestore, make_keyframes: Callable) -> None:
    msg = keyframe_poses_to_msg(typestore, make_keyframes(), WORLD_FRAME)
    with pytest.raises(InputError, match=f'expected a {HAND_FRAME_MSG} message, got '
                                         f'{KEYFRAME_POSES_MSG}'):
        msg_to_frame_result(msg)


def test_unknown_side_raises(typestore: Typestore, make_frame: MakeFrame) -> None:
    msg = hand_to_msg(typestore, make_frame().hand(LEFT))
    msg.side = 7
    with pytest.raises(InputError, match='side must be 0 \\(LEFT\\) or 1 \\(RIGHT\\), got 7'):
        msg_to_hand(msg)


def test_short_joint_array_raises(typestore: Typestore, make_frame: MakeFrame) -> None:
    msg = hand_to_msg(typestore, make_frame().hand(LEFT))
    msg.joints_2d = msg.joints_2d[:10]
    with pytest.raises(InputError, match='Hand.joints_2d must hold 42 values'):
        msg_to_hand(msg)


def test_negative_frame_index_raises(typestore: Typestore, make_frame: MakeFrame) -> None:
    frame = dataclasses.replace(make_frame(), frame_index=-1)
    with pytest.raises(InputError, match='frame_index must be in \\[0, 4294967295\\]'):
        frame_result_to_msg(typestore, frame, WORLD_FRAME)


def test_keyframe_update_with_mismatched_lengths_raises(make_keyframes: Callable) -> None:
    update = make_keyframes(3)
    with pytest.raises(InputError, match='same length, got \\(2, 3, 3\\)'):
        dataclasses.replace(update, frame_indices=update.frame_indices[:2])


def test_empty_keyframe_update_needs_a_stamp(typestore: Typestore) -> None:
    empty = KeyframePoseUpdate(frame_indices=(), stamps_ns=(), poses=())
    with pytest.raises(InputError, match='empty: pass stamp_ns'):
        keyframe_poses_to_msg(typestore, empty, WORLD_FRAME)
    msg = keyframe_poses_to_msg(typestore, empty, WORLD_FRAME, stamp_ns=BASE_STAMP_NS)
    assert msg_to_keyframe_poses(msg) == empty


def test_plain_jazzy_typestore_raises(make_frame: MakeFrame) -> None:
    with pytest.raises(ConfigError, match='typestore has no message type .*build_typestore'):
        frame_result_to_msg(get_typestore(Stores.ROS2_JAZZY), make_frame(), WORLD_FRAME)


def _pose_stamped(typestore: Typestore, rng: np.random.Generator) -> object:
    """Build a rosbags geometry_msgs/msg/PoseStamped with a random pose."""
    header = typestore.types['std_msgs/msg/Header'](
        stamp=stamp_from_ns(typestore, BASE_STAMP_NS), frame_id=WORLD_FRAME)
    return typestore.types[POSE_STAMPED_MSG](header=header,
                                             pose=pose_to_msg(typestore, random_pose(rng)))


@pytest.mark.ros
@pytest.mark.filterwarnings('ignore:module .sre_:DeprecationWarning')
def test_rosbags_cdr_is_readable_by_rclpy(typestore: Typestore, rng: np.random.Generator) -> None:
    serialization = pytest.importorskip('rclpy.serialization')
    geometry_msgs = pytest.importorskip('geometry_msgs.msg')
    ours = _pose_stamped(typestore, rng)
    theirs = serialization.deserialize_message(
        bytes(typestore.serialize_cdr(ours, POSE_STAMPED_MSG)), geometry_msgs.PoseStamped)
    assert theirs.header.frame_id == WORLD_FRAME
    assert (theirs.header.stamp.sec, theirs.header.stamp.nanosec) == (
        ours.header.stamp.sec, ours.header.stamp.nanosec)
    got = theirs.pose
    assert_pose_close(msg_to_pose(got), msg_to_pose(ours.pose))
    # Back again: rclpy's bytes decode with rosbags to the same values.
    back = typestore.deserialize_cdr(serialization.serialize_message(theirs), POSE_STAMPED_MSG)
    assert back.pose.orientation == ours.pose.orientation
    assert back.pose.position == ours.pose.position
