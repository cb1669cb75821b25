"""The shipped sample bag is what the generator makes from ``data/sample_bag.yaml``."""

from dataclasses import replace
from pathlib import Path

from infinihand_ros.bag.camera_msgs import camera_info_to_intrinsics
from infinihand_ros.bag.camera_msgs import compressed_msg_to_image
from infinihand_ros.bag.messages import msg_to_frame_result
from infinihand_ros.bag.messages import msg_to_pose
from infinihand_ros.core import topics
from infinihand_ros.core.errors import InputError
from infinihand_ros.synth.sample_bag import load_sample_settings
from infinihand_ros.synth.sample_bag import MAX_BAG_BYTES
from infinihand_ros.synth.sample_bag import sample_bag_path
from infinihand_ros.synth.sample_bag import sample_sequence
from infinihand_ros.synth.sample_bag import SampleSpec
from infinihand_ros.synth.sample_bag import write_sample_bag
import numpy as np
import pytest
from rosbags.highlevel import AnyReader

#: JPEG at the configured quality keeps the images this close to the rendered ones.
MIN_PSNR_DB = 30.0


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    rmse = np.sqrt(np.mean((a.astype(float) - b.astype(float)) ** 2))
    return float(20.0 * np.log10(255.0 / max(rmse, 1e-9)))


def test_sample_bag_is_small_and_complete() -> None:
    settings = load_sample_settings()
    bag = sample_bag_path()
    assert sum(f.stat().st_size for f in bag.iterdir()) <= MAX_BAG_BYTES
    with AnyReader([bag]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts == {topic: settings.spec.frames for topic in (
        topics.COMPRESSED_IMAGE_TOPIC, topics.CAMERA_INFO_TOPIC, topics.GT_CAMERA_POSE_TOPIC,
        topics.GT_HANDS_TOPIC)}


@pytest.mark.slow
def test_sample_bag_matches_the_generator() -> None:
    settings = load_sample_settings()
    frames = iter(sample_sequence(settings))
    checked = 0
    with AnyReader([sample_bag_path()]) as reader:
        by_topic = {c.topic: c for c in reader.connections}
        images = reader.messages(connections=[by_topic[topics.COMPRESSED_IMAGE_TOPIC]])
        infos = reader.messages(connections=[by_topic[topics.CAMERA_INFO_TOPIC]])
        poses = reader.messages(connections=[by_topic[topics.GT_CAMERA_POSE_TOPIC]])
        hands = reader.messages(connections=[by_topic[topics.GT_HANDS_TOPIC]])
        for messages in zip(images, infos, poses, hands):
            image, info, pose, hand_frame = (reader.deserialize(raw, conn.msgtype)
                                             for conn, _, raw in messages)
            frame = next(frames)
            assert {stamp for _, stamp, _ in messages} == {frame.timestamp_ns}
            assert _psnr(compressed_msg_to_image(image), frame.rgb) > MIN_PSNR_DB
            assert camera_info_to_intrinsics(info) == frame.intrinsics
            np.testing.assert_allclose(msg_to_pose(pose.pose).matrix(),
                                       frame.camera_pose.matrix(), atol=1e-9)
            result = msg_to_frame_result(hand_frame)
            for truth in frame.hands:
                np.testing.assert_allclose(result.hand(truth.side).joints_world,
                                           truth.joints_world, atol=1e-9)
            checked += 1
    assert checked == settings.spec.frames


def test_oversized_sample_bag_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    settings = load_sample_settings()
    monkeypatch.setattr('infinihand_ros.synth.sample_bag.MAX_BAG_BYTES', 1000)
    small = replace(settings, spec=SampleSpec(seed=1, frames=2))
    with pytest.raises(InputError, match='over the 0 MiB limit'):
        write_sample_bag(tmp_path / 'bag', small)
    assert list(tmp_path.iterdir()) == []
