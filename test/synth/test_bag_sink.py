"""Synthetic bags: readable by rosbags and by rclpy, ground truth intact, written atomically."""

from pathlib import Path

from infinihand_ros.bag.camera_msgs import camera_info_to_intrinsics
from infinihand_ros.bag.camera_msgs import compressed_msg_to_image
from infinihand_ros.bag.camera_msgs import msg_to_image
from infinihand_ros.bag.messages import msg_to_frame_result
from infinihand_ros.bag.messages import msg_to_pose
from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.core import topics
from infinihand_ros.core.errors import InputError
from infinihand_ros.synth.bag_sink import BagOptions
from infinihand_ros.synth.bag_sink import BagSink
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
from rosbags.highlevel import AnyReader

CONFIG = SynthConfig(width=96, height=72)


def _write(path: Path, options: BagOptions = BagOptions()) -> list:
    sequence = SyntheticSequence(CONFIG, seed=2, num_frames=4)
    frames = list(sequence)
    with BagSink(path, options) as sink:
        for frame in frames:
            sink.add(frame)
    return frames


@pytest.mark.parametrize('options', [
    BagOptions('mcap'), BagOptions('mcap', compress=True), BagOptions('sqlite3'),
    BagOptions('mcap', image_codec='png'), BagOptions('mcap', image_codec='jpeg')])
def test_bag_round_trip(tmp_path: Path, options: BagOptions) -> None:
    frames = _write(tmp_path / 'bag', options)
    image_topic = options.image_topic()[0]
    by_topic: dict[str, list] = {}
    with AnyReader([tmp_path / 'bag']) as reader:
        assert {c.topic for c in reader.connections} == {
            image_topic, topics.CAMERA_INFO_TOPIC, topics.GT_CAMERA_POSE_TOPIC,
            topics.GT_HANDS_TOPIC}
        for connection, stamp, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            assert ns_from_stamp(msg.header.stamp) == stamp
            by_topic.setdefault(connection.topic, []).append(msg)
    assert all(len(msgs) == len(frames) for msgs in by_topic.values())
    for frame, image, info, pose, hands in zip(frames, *(by_topic[t] for t in (
            image_topic, topics.CAMERA_INFO_TOPIC, topics.GT_CAMERA_POSE_TOPIC,
            topics.GT_HANDS_TOPIC))):
        if options.image_codec == 'jpeg':  # lossy: close (PSNR > 28 dB), channels in order
            decoded = compressed_msg_to_image(image).astype(float)
            rmse = np.sqrt(np.mean((decoded - frame.rgb) ** 2))
            assert 20.0 * np.log10(255.0 / rmse) > 28.0
            assert rmse < 0.5 * np.sqrt(np.mean((decoded[:, :, ::-1] - frame.rgb) ** 2))
        else:
            decoded = (msg_to_image(image) if options.image_codec == 'raw'
                       else compressed_msg_to_image(image))
            np.testing.assert_array_equal(decoded, frame.rgb)
        assert camera_info_to_intrinsics(info) == frame.intrinsics
        np.testing.assert_allclose(msg_to_pose(pose.pose).matrix(), frame.camera_pose.matrix(),
                                   atol=1e-12)
        result = msg_to_frame_result(hands)
        assert result.frame_index == frame.index
        for truth in frame.hands:
            decoded = result.hand(truth.side)
            assert decoded.confidence == (1.0 if truth.visible else 0.0)
            np.testing.assert_allclose(decoded.joints_world, truth.joints_world, atol=1e-12)
            np.testing.assert_allclose(decoded.mano_cam.hand_pose, truth.mano_cam.hand_pose)


@pytest.mark.ros
def test_rclpy_deserializes_the_bag(tmp_path: Path) -> None:
    serialization = pytest.importorskip('rclpy.serialization')
    sensor_msgs = pytest.importorskip('sensor_msgs.msg')
    geometry_msgs = pytest.importorskip('geometry_msgs.msg')
    frames = _write(tmp_path / 'bag')
    classes = {topics.IMAGE_TOPIC: sensor_msgs.Image,
               topics.CAMERA_INFO_TOPIC: sensor_msgs.CameraInfo,
               topics.GT_CAMERA_POSE_TOPIC: geometry_msgs.PoseStamped}
    decoded = 0
    with AnyReader([tmp_path / 'bag']) as reader:
        for connection, _, raw in reader.messages():
            if connection.topic in classes:
                msg = serialization.deserialize_message(bytes(raw), classes[connection.topic])
                decoded += 1
                if connection.topic == topics.IMAGE_TOPIC:
                    np.testing.assert_array_equal(msg_to_image(msg), frames[0].rgb)
                    break
    assert decoded >= 1


def test_failed_write_leaves_nothing(tmp_path: Path) -> None:
    sequence = SyntheticSequence(CONFIG, seed=2, num_frames=1)
    with pytest.raises(RuntimeError, match='boom'):
        with BagSink(tmp_path / 'bag') as sink:
            sink.add(sequence.frame(0))
            raise RuntimeError('boom')
    assert list(tmp_path.iterdir()) == []


def test_existing_bag_is_not_overwritten(tmp_path: Path) -> None:
    (tmp_path / 'bag').mkdir()
    with pytest.raises(InputError, match='already exists'):
        with BagSink(tmp_path / 'bag'):
            pass
    with pytest.raises(InputError, match="bag format must be one of .* got 'rosbag1'"):
        BagOptions(storage='rosbag1')
