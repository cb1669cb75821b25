"""Tests of engine/stream_policy.py: stamp order and restarts, alone and in the engine's push."""

from dataclasses import replace

from engine_configs import seeded_tiny
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.stage_timing import STAGE_FINISH
from infinihand_ros.engine.stage_timing import STAGE_HANDS
from infinihand_ros.engine.stage_timing import STAGE_PREPARE
from infinihand_ros.engine.stage_timing import STAGES
from infinihand_ros.engine.stream_policy import StreamPolicy
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.engine.timestamps import StampStep
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest

CONFIG = seeded_tiny(keyframe_interval=2)
LAST = 10 * NS_PER_S


@pytest.fixture(scope='module')
def model():
    """Build the tiny model once (seeded, untrained)."""
    return build_model(CONFIG)


@pytest.fixture(scope='module')
def frames() -> list:
    """Render 5 synthetic frames at 10 fps (stamps 0.1 s apart)."""
    return list(SyntheticSequence(SynthConfig(width=320, height=240), seed=5, num_frames=5))


def _push(engine: StreamingEngine, frames: list) -> list:
    results = []
    for frame in frames:
        results += engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
    return results


def test_the_policy_admits_later_stamps_refuses_late_ones_and_restarts_far_back() -> None:
    policy = StreamPolicy(restart_after_s=1.0)
    assert policy.admit(LAST) is StampStep.NEXT  # the first frame
    policy.accept(LAST)
    with pytest.raises(InputError, match='a duplicate of the previous'):
        policy.admit(LAST)
    with pytest.raises(InputError, match=f"earlier than the previous frame's {LAST} ns"):
        policy.admit(LAST - NS_PER_S)  # exactly the restart gap back: still late
    assert policy.out_of_order == 2 and policy.restarts == 0
    assert policy.step(LAST - NS_PER_S - 1) is StampStep.RESTART  # asking changes nothing
    assert policy.restarts == 0 and policy.last_ns == LAST
    assert policy.admit(LAST - NS_PER_S - 1) is StampStep.RESTART
    assert policy.restarts == 1
    assert policy.admit(LAST + 1) is StampStep.NEXT
    policy.accept(None)  # a new stream: any stamp continues it
    assert policy.admit(0) is StampStep.NEXT


def test_a_zero_restart_gap_never_restarts() -> None:
    policy = StreamPolicy(restart_after_s=0.0)
    policy.accept(LAST)
    with pytest.raises(InputError, match='earlier than'):
        policy.admit(0)
    assert (policy.out_of_order, policy.restarts) == (1, 0)


def test_a_late_image_is_refused_counted_and_the_stream_goes_on(model, frames: list) -> None:
    """Stamps 0.2 s back (restart_after_s 1 s): out of order; the stream continues unchanged."""
    with StreamingEngine(CONFIG, model) as engine:
        results = _push(engine, frames[:4])
        assert engine.last_accepted_ns == frames[3].timestamp_ns
        assert engine.stamp_step(frames[1].timestamp_ns) is StampStep.OUT_OF_ORDER
        assert engine.stamp_step(frames[4].timestamp_ns) is StampStep.NEXT
        for late in (frames[1], frames[3]):
            with pytest.raises(InputError, match='earlier than|duplicate'):
                engine.push(late.rgb, late.timestamp_ns, late.intrinsics)
        assert engine.statistics['frames_out_of_order'] == 2
        assert engine.statistics['stream_restarts'] == 0
        results += _push(engine, frames[4:]) + engine.flush()
        assert engine.statistics['frames_pushed'] == 5
    assert [result.frame_index for result in results] == [0, 1, 2, 3, 4]


def test_an_image_far_back_restarts_the_stream_and_its_world_frame(model, frames: list) -> None:
    """A replay loop (the same stamps again, > restart_after_s back): one restart, a fresh stream.

    The second pass gives what a new engine gives for those frames: frame indices from 0, the
    world frame at its first frame.
    """
    config = replace(CONFIG, restart_after_s=0.15)
    with StreamingEngine(config, model) as engine:
        _push(engine, frames[:4])
        assert engine.stamp_step(frames[0].timestamp_ns) is StampStep.RESTART
        again = _push(engine, frames[:3]) + engine.flush()
        assert engine.statistics['stream_restarts'] == 1
        assert engine.statistics['frames_out_of_order'] == 0
        assert engine.statistics['frames_pushed'] == 3
    with StreamingEngine(config, model) as fresh_engine:
        fresh = _push(fresh_engine, frames[:3]) + fresh_engine.flush()
    assert [result.frame_index for result in again] == [0, 1, 2]
    np.testing.assert_allclose(again[0].camera_pose.matrix(), np.eye(4), atol=1e-6)
    for a, b in zip(fresh, again):
        assert a.timestamp_ns == b.timestamp_ns
        np.testing.assert_allclose(a.camera_pose.matrix(), b.camera_pose.matrix(), atol=1e-6)


def test_a_bad_image_far_back_restarts_nothing(model, frames: list) -> None:
    config = replace(CONFIG, restart_after_s=0.15)
    with StreamingEngine(config, model) as engine:
        _push(engine, frames[:4])
        with pytest.raises(InputError):
            engine.push(frames[0].rgb[:, :, :2], frames[0].timestamp_ns)
        assert engine.statistics['stream_restarts'] == 0
        assert engine.statistics['frames_pushed'] == 4


def test_the_stage_timer_hears_of_each_stage(model, frames: list) -> None:
    """stage_timer gets (stage, seconds) for the engine's stages, named in STAGES."""
    heard: list[tuple[str, float]] = []
    with StreamingEngine(CONFIG, model) as engine:
        engine.stage_timer = lambda name, seconds: heard.append((name, seconds))
        results = _push(engine, frames[:3]) + engine.flush()
    names = {name for name, _ in heard}
    assert {STAGE_PREPARE, STAGE_HANDS, STAGE_FINISH} <= names <= set(STAGES)
    assert sum(name == STAGE_FINISH for name, _ in heard) == len(results) == 3
    assert all(seconds >= 0.0 for _, seconds in heard)
