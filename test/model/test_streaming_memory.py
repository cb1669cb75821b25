"""Tests of model/streaming_memory.py: schedule, cache sizes, block == frame-by-frame."""

from infinihand_ros.core.errors import InputError
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.geometry_stream import GeometryStream
from infinihand_ros.model.streaming_memory import FrameSchedule
from infinihand_ros.model.streaming_memory import KVMemory
import pytest
import torch

SPECIAL = 6


def _run_block(memory: KVMemory, schedule: FrameSchedule, flags: list[bool], per_frame: int,
               layers: int) -> None:
    """Push random keys/values of one block through every layer of ``memory``."""
    plan = schedule.plan(flags)
    memory.begin(plan, per_frame, torch.device('cpu'))
    tokens = torch.randn(1, 2, len(flags) * per_frame, 8)
    for layer in range(layers):
        memory.context(layer).attend(tokens, tokens, tokens)
    memory.commit()
    schedule.commit(plan)


@pytest.mark.parametrize('num_frames', [1, 3, 4, 7, 12, 25, 40])
def test_cached_tokens_are_anchor_plus_window_plus_trajectory(num_frames: int) -> None:
    """After N post-anchor keyframes each layer holds anchor + window + 6 x evicted tokens."""
    anchor, window, per_frame, layers = 3, 5, 20, 2
    memory = KVMemory(layers, window, SPECIAL)
    schedule = FrameSchedule(anchor)
    _run_block(memory, schedule, [True] * anchor, per_frame, layers)
    for _ in range(num_frames):
        _run_block(memory, schedule, [True], per_frame, layers)
    evicted = max(0, num_frames - window)
    expected = anchor * per_frame + min(num_frames, window) * per_frame + SPECIAL * evicted
    assert [memory.cached_tokens(layer) for layer in range(layers)] == [expected] * layers


def test_trajectory_memory_is_bounded_on_long_streams() -> None:
    """With a trajectory cap the cache stops growing, however long the stream."""
    anchor, window, per_frame, cap = 2, 3, 10, 8
    memory = KVMemory(1, window, SPECIAL, max_trajectory_frames=cap)
    schedule = FrameSchedule(anchor)
    _run_block(memory, schedule, [True] * anchor, per_frame, 1)
    sizes = []
    for _ in range(200):
        _run_block(memory, schedule, [True], per_frame, 1)
        sizes.append(memory.cached_tokens(0))
    full = (anchor + window) * per_frame
    assert max(sizes) <= full + SPECIAL * (cap + cap // 4)
    assert min(sizes[-50:]) >= full + SPECIAL * cap


def test_non_keyframes_attend_without_being_stored() -> None:
    """A non-keyframe leaves the cache and the time index unchanged."""
    memory = KVMemory(1, 4, SPECIAL)
    schedule = FrameSchedule(1)
    _run_block(memory, schedule, [True], 10, 1)
    before = memory.cached_tokens(0)
    _run_block(memory, schedule, [False], 10, 1)
    assert memory.cached_tokens(0) == before
    assert schedule.plan([True]).time_index == (1,)
    assert schedule.frames_seen == 2


def test_schedule_plans_anchors_then_keyframes() -> None:
    """Anchors are stored whatever their flag; time indices count stored frames only."""
    schedule = FrameSchedule(2)
    anchors = schedule.plan([False, False])
    assert anchors.is_anchor and anchors.stored == (True, True)
    assert anchors.time_index == (0, 1)
    schedule.commit(anchors)
    block = schedule.plan([True, False, True])
    assert not block.is_anchor
    assert block.stored == (True, False, True)
    assert block.time_index == (2, 3, 3)
    assert block.keyframes_before == (0, 1, 1)


def test_schedule_rejects_a_block_across_the_anchor_end() -> None:
    """A block mixing anchors and later frames is refused with the split to use."""
    with pytest.raises(InputError, match='first 2 frames'):
        FrameSchedule(2).plan([True] * 3)


def test_schedule_rejects_out_of_order_commit() -> None:
    """Committing a stale plan is an error."""
    schedule = FrameSchedule(1)
    plan = schedule.plan([True])
    schedule.commit(plan)
    with pytest.raises(ValueError, match='in order'):
        schedule.commit(plan)


def _frames(rng, count: int) -> torch.Tensor:
    return torch.from_numpy(rng.random((1, count, 3, 56, 70), dtype='float32'))


def test_window_in_one_call_equals_frame_by_frame(micro_model: GeometryModel, rng) -> None:
    """Causal block attention reproduces per-frame streaming, eviction and skips included."""
    anchors, earlier, window = _frames(rng, 2), _frames(rng, 2), _frames(rng, 5)
    later = _frames(rng, 1)
    flags = [True, False, True, True, True]  # window 2: frames leave the window mid-block
    one_call, one_by_one = GeometryStream(micro_model), GeometryStream(micro_model)
    with torch.no_grad():
        for stream in (one_call, one_by_one):
            stream.step(anchors)
            stream.step(earlier[:, :1])
            stream.step(earlier[:, 1:])
        block = one_call.step(window, flags)
        singles = [one_by_one.step(window[:, i:i + 1], flag) for i, flag in enumerate(flags)]
        after_block, after_singles = one_call.step(later), one_by_one.step(later)
    for name in ('pose_encoding', 'depth', 'depth_conf', 'hand_masks', 'patch_features'):
        expected = torch.cat([getattr(single, name) for single in singles], dim=1)
        torch.testing.assert_close(getattr(block, name), expected, rtol=1e-4, atol=1e-4,
                                   msg=name)
        torch.testing.assert_close(getattr(after_block, name), getattr(after_singles, name),
                                   rtol=1e-4, atol=1e-4, msg=name)
    for memory_a, memory_b in zip(one_call.memories, one_by_one.memories):
        assert memory_a.cached_tokens(0) == memory_b.cached_tokens(0)


def test_reset_empties_the_stream(micro_model: GeometryModel, rng) -> None:
    """After reset the same frames give the same outputs as on a fresh stream."""
    stream = GeometryStream(micro_model)
    frames = _frames(rng, 3)
    with torch.no_grad():
        first = stream.step(frames)
        stream.step(_frames(rng, 1))
        stream.reset()
        assert stream.aggregator_memory.cached_tokens(0) == 0
        again = stream.step(frames)
    torch.testing.assert_close(first.pose_encoding, again.pose_encoding)


def test_stream_splits_a_call_at_the_anchor_end(micro_model: GeometryModel, rng) -> None:
    """A first call longer than the anchors equals anchors then the rest."""
    frames = _frames(rng, 4)
    split, joined = GeometryStream(micro_model), GeometryStream(micro_model)
    with torch.no_grad():
        expected = torch.cat((split.step(frames[:, :2]).depth, split.step(frames[:, 2:]).depth),
                             dim=1)
        torch.testing.assert_close(joined.step(frames).depth, expected)


def test_stream_rejects_bad_input(micro_model: GeometryModel) -> None:
    """Wrong shapes, sizes and flag counts raise InputError naming the fix."""
    stream = GeometryStream(micro_model)
    with pytest.raises(InputError, match='multiple of the patch size'):
        stream.step(torch.zeros(1, 1, 3, 50, 70))
    with pytest.raises(InputError, match=r'\(1, S, 3, H, W\)'):
        stream.step(torch.zeros(1, 3, 56, 70))
    with pytest.raises(InputError, match='2 keyframe flags for 1 frames'):
        stream.step(torch.zeros(1, 1, 3, 56, 70), [True, False])


def test_camera_head_cache_grows_by_one_token_per_stored_frame(micro_model, rng) -> None:
    """The camera head's causal cache keeps one token per anchor or keyframe, never evicted."""
    stream = GeometryStream(micro_model)
    with torch.no_grad():
        stream.step(_frames(rng, 2))
        for flag in (True, False, True, True, True):
            stream.step(_frames(rng, 1), flag)
    camera_memory = stream.camera_memory
    assert [camera_memory.cached_tokens(layer) for layer in range(camera_memory.num_layers)] \
        == [2 + 4] * camera_memory.num_layers
