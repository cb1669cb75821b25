"""The untrained tiny model runs end to end on the bundled sample bag."""

from engine_configs import seeded_tiny
from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.synth.sample_bag import sample_bag_path
import numpy as np
import pytest

FRAMES = 30


@pytest.mark.slow
def test_one_result_per_bag_frame_with_the_right_shapes() -> None:
    frames = list(read_camera_frames(sample_bag_path(), max_frames=FRAMES))
    with StreamingEngine(seeded_tiny(mode='windowed', window=8, depth_maps=True)) as engine:
        results = []
        for frame in frames:
            results += engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
        results += engine.flush()
    assert [r.timestamp_ns for r in results] == [f.timestamp_ns for f in frames]
    for result, frame in zip(results, frames):
        assert result.intrinsics == frame.intrinsics
        assert result.depth.shape == (378, 518) and np.all(np.isfinite(result.depth))
        assert np.all(np.isfinite(result.camera_pose.matrix()))
        for hand in result.hands:
            assert hand.joints_world.shape == (21, 3) and hand.joints_2d.shape == (21, 2)
            assert np.all(np.isfinite(hand.joints_world))
