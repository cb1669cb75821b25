"""The streaming engine on synthetic frames with the untrained tiny model."""

from dataclasses import replace

from infinihand_ros.core.errors import InputError
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest

CONFIG = EngineConfig(keyframe_interval=2)
NUM_FRAMES = 7


@pytest.fixture(scope='module')
def model():
    """Build the tiny model once (seeded, untrained)."""
    return build_model(CONFIG)


@pytest.fixture(scope='module')
def frames() -> list:
    """Render a short synthetic sequence at 320x240 (letterboxed to the model's 224x168)."""
    return list(SyntheticSequence(SynthConfig(width=320, height=240), seed=5,
                                  num_frames=NUM_FRAMES))


def _run(engine: StreamingEngine, frames: list, with_intrinsics: bool = True) -> list:
    results = []
    for frame in frames:
        results += engine.push(frame.rgb, frame.timestamp_ns,
                               frame.intrinsics if with_intrinsics else None)
    return results + engine.flush()


def test_one_result_per_frame_in_order(model, frames: list) -> None:
    results = _run(StreamingEngine(CONFIG, model), frames)
    assert [r.frame_index for r in results] == list(range(NUM_FRAMES))
    assert [r.timestamp_ns for r in results] == [f.timestamp_ns for f in frames]
    # Two anchors, then every second frame is a keyframe.
    assert [r.is_keyframe for r in results] == [True, True, True, False, True, False, True]
    for result, frame in zip(results, frames):
        assert result.intrinsics == frame.intrinsics
        assert np.all(np.isfinite(result.camera_pose.matrix()))
        assert (result.depth.shape == (240, 320)) if result.is_keyframe else result.depth is None
        for hand in result.hands:
            np.testing.assert_allclose(hand.joints_world,
                                       result.camera_pose.to_world(hand.joints_cam), atol=1e-9)
            assert 0.5 < hand.confidence <= 1.0


def test_windowed_mode_gives_the_per_frame_results(model, frames: list) -> None:
    per_frame = _run(StreamingEngine(CONFIG, model), frames)
    with StreamingEngine(replace(CONFIG, mode='windowed', window=3), model) as engine:
        windowed = _run(engine, frames)
    assert len(windowed) == len(per_frame)
    for a, b in zip(per_frame, windowed):
        np.testing.assert_allclose(a.camera_pose.matrix(), b.camera_pose.matrix(), atol=1e-4)
        assert [h.side for h in a.hands] == [h.side for h in b.hands]
        for hand_a, hand_b in zip(a.hands, b.hands):
            np.testing.assert_allclose(hand_a.joints_world, hand_b.joints_world, atol=1e-3)


def test_bad_frames_raise_and_leave_the_stream_intact(model, frames: list) -> None:
    clean = _run(StreamingEngine(CONFIG, model), frames[:4])
    engine = StreamingEngine(CONFIG, model)
    results = []
    for index, frame in enumerate(frames[:4]):
        if index == 2:
            with pytest.raises(InputError, match='expected uint8 pixels'):
                engine.push(frame.rgb.astype(np.float32), frame.timestamp_ns)
            with pytest.raises(InputError, match='image is empty'):
                engine.push(np.zeros((0, 0, 3), np.uint8), frame.timestamp_ns)
            with pytest.raises(InputError, match='intrinsics are for'):
                engine.push(frame.rgb[:100], frame.timestamp_ns, frame.intrinsics)
        results += engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
    results += engine.flush()
    assert [r.frame_index for r in results] == [0, 1, 2, 3]
    for a, b in zip(clean, results):
        np.testing.assert_allclose(a.camera_pose.matrix(), b.camera_pose.matrix(), atol=1e-6)


def test_reset_starts_a_new_sequence(model, frames: list) -> None:
    engine = StreamingEngine(CONFIG, model)
    first = _run(engine, frames[:3])
    engine.reset()
    second = _run(engine, frames[:3])
    assert [r.frame_index for r in second] == [0, 1, 2]
    for a, b in zip(first, second):
        np.testing.assert_allclose(a.camera_pose.matrix(), b.camera_pose.matrix(), atol=1e-6)


def test_predicted_field_of_view_without_intrinsics(model, frames: list) -> None:
    results = _run(StreamingEngine(CONFIG, model), frames[:3], with_intrinsics=False)
    for result in results:
        intrinsics = result.intrinsics
        assert (intrinsics.width, intrinsics.height) == (320, 240)
        # The model's principal point is the image centre (W/2, H/2, as Intrinsics.from_fov);
        # letterboxing keeps it there up to the half-pixel of the resampling.
        assert intrinsics.cx == pytest.approx(160.0, abs=0.5)
        assert intrinsics.cy == pytest.approx(120.0, abs=0.5)
        # Untrained FoVs are arbitrary, but clamped to the configured range.
        fov_h, fov_w = np.degrees(intrinsics.fov())
        assert 4.9 < fov_h < 170.1 and 4.9 < fov_w < 170.1


def test_bundle_adjustment_keeps_the_raw_poses(model, frames: list) -> None:
    plain = _run(StreamingEngine(CONFIG, model), frames[:4])
    with StreamingEngine(replace(CONFIG, bundle_adjustment=True), model) as engine:
        adjusted = _run(engine, frames[:4])
    for a, b in zip(plain, adjusted):
        assert a.raw_camera_pose is None
        # No BA call yet (the pool has not triggered): the correction is the identity.
        np.testing.assert_allclose(b.raw_camera_pose.matrix(), a.camera_pose.matrix(), atol=1e-6)
        np.testing.assert_allclose(b.camera_pose.matrix(), a.camera_pose.matrix(), atol=1e-6)
