"""Camera frames from bags: raw and compressed images, intrinsics paired, bad images skipped."""

import dataclasses
from pathlib import Path

from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.convert.bag_frames import read_bag_frames
from infinihand_ros.convert.frame_log import FrameLog
from infinihand_ros.core import topics
from infinihand_ros.core.errors import BagError
from infinihand_ros.synth.bag_sink import BagOptions
from infinihand_ros.synth.bag_sink import BagSink
from infinihand_ros.synth.sample_bag import sample_bag_path
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest


@pytest.mark.parametrize('codec', ['raw', 'png'])
def test_frames_come_back_with_their_intrinsics(tmp_path: Path, codec: str) -> None:
    frames = list(SyntheticSequence(SynthConfig(width=64, height=48), seed=2, num_frames=3))
    with BagSink(tmp_path / 'bag', BagOptions(image_codec=codec)) as sink:
        for frame in frames:
            sink.add(frame)
    read = list(read_camera_frames(tmp_path / 'bag'))
    assert [f.timestamp_ns for f in read] == [f.timestamp_ns for f in frames]
    for got, frame in zip(read, frames):
        np.testing.assert_array_equal(got.rgb, frame.rgb)
        assert got.intrinsics == frame.intrinsics
    assert len(list(read_camera_frames(tmp_path / 'bag', max_frames=2))) == 2


def test_sample_bag_frames() -> None:
    read = list(read_camera_frames(sample_bag_path(), max_frames=3))
    assert [f.rgb.shape for f in read] == [(378, 518, 3)] * 3
    assert all(f.intrinsics is not None for f in read)


def test_undecodable_image_is_skipped(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    frames = list(SyntheticSequence(SynthConfig(width=64, height=48), seed=2, num_frames=2))
    sink = BagSink(tmp_path / 'bag', BagOptions(image_codec='png'))
    with sink:
        sink.add(frames[0])
        # A corrupt compressed image between two good frames.
        store = sink.typestore
        bad = store.types['sensor_msgs/msg/CompressedImage'](
            header=store.types['std_msgs/msg/Header'](
                stamp=store.types['builtin_interfaces/msg/Time'](sec=1767225600, nanosec=5),
                frame_id='camera'),
            format='rgb8; png compressed bgr8', data=np.frombuffer(b'garbage!', np.uint8))
        connection = sink._connections[topics.COMPRESSED_IMAGE_TOPIC]
        sink._writer.write(connection, frames[0].timestamp_ns + 5,
                           store.serialize_cdr(bad, 'sensor_msgs/msg/CompressedImage'))
        sink.add(frames[1])
    read = list(read_camera_frames(tmp_path / 'bag'))
    assert [f.timestamp_ns for f in read] == [frames[0].timestamp_ns, frames[1].timestamp_ns]
    assert 'skipping the image stamped' in caplog.text


def test_bag_without_images(tmp_path: Path) -> None:
    with pytest.raises(BagError, match='no image topic'):
        list(read_camera_frames(sample_bag_path(), image_topic='/ground_truth/hands'))


@pytest.mark.parametrize('model, coefficients', [
    ('plumb_bob', (-0.25, 0.08, 0.001, -0.002, 0.01)),
    ('rational_polynomial', (-0.2, 0.05, 0.001, 0.001, 0.01, 0.02, 0.01, 0.005)),
    ('equidistant', (0.05, -0.01, 0.003, -0.001)),
])
def test_camera_info_distortion_is_read_from_a_bag(tmp_path: Path, model: str,
                                                   coefficients: tuple) -> None:
    """A bag's CameraInfo model and coefficients reach the frames, as the node's would."""
    frames = list(SyntheticSequence(SynthConfig(width=64, height=48), seed=2, num_frames=2))
    lens = dataclasses.replace(frames[0].intrinsics, distortion_model=model,
                               distortion=coefficients)
    with BagSink(tmp_path / 'bag') as sink:
        for frame in frames:
            sink.add(dataclasses.replace(frame, intrinsics=lens))
    for read in (list(read_camera_frames(tmp_path / 'bag')),
                 list(read_bag_frames(tmp_path / 'bag', None, FrameLog()))):
        assert [f.intrinsics for f in read] == [lens, lens]
