"""Tests of model/streaming_memory.py: schedule, cache sizes, block == frame-by-frame."""

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.errors import ModelOutputError
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
    """With a trajectory cap the cache and its buffers stop growing, however long the stream."""
    anchor, window, per_frame, cap = 2, 3, 10, 8
    memory = KVMemory(1, window, SPECIAL, max_trajectory_frames=cap)
    schedule = FrameSchedule(anchor)
    _run_block(memory, schedule, [True] * anchor, per_frame, 1)
    sizes, allocated = [], []
    for _ in range(200):
        _run_block(memory, schedule, [True], per_frame, 1)
        sizes.append(memory.cached_tokens(0))
        allocated.append(memory.allocated_tokens())
    full = (anchor + window) * per_frame
    assert sizes[-1] == max(sizes) == full + SPECIAL * cap
    assert len(set(allocated[20:])) == 1


def test_steady_state_frames_write_in_place() -> None:
    """Once the window and trajectory are full, frames reuse the same buffer (no reallocation)."""
    memory = KVMemory(2, 3, SPECIAL, max_trajectory_frames=4)
    schedule = FrameSchedule(1)
    with torch.inference_mode():
        _run_block(memory, schedule, [True], 10, 2)
        _run_block(memory, schedule, [True, False, True, True], 10, 2)  # the largest block
        for _ in range(12):
            _run_block(memory, schedule, [True], 10, 2)
        grown, allocated = memory.reallocations, memory.allocated_tokens()
        for _ in range(50):
            for flags in ([True], [False], [True, True, False, True], [True]):
                _run_block(memory, schedule, flags, 10, 2)
    assert memory.reallocations == grown
    assert memory.allocated_tokens() == allocated == (4 + 1 + 3) * 10 + 4 * SPECIAL


class _ReferenceCache:
    """LingBot-Map's procedure written plainly: append, evict to the window, then attend."""

    def __init__(self, window: int, cap: int | None) -> None:
        self.window, self.cap = window, cap
        self.anchors: list[torch.Tensor] = []
        self.frames: list[torch.Tensor] = []
        self.trajectory: list[torch.Tensor] = []

    def step(self, query: torch.Tensor, kv: torch.Tensor, anchor: bool, stored: bool
             ) -> torch.Tensor:
        if anchor:
            self.anchors.append(kv)
        elif stored:
            self.frames.append(kv)
            while len(self.frames) > self.window:
                self.trajectory.append(self.frames.pop(0)[..., :SPECIAL, :])
            if self.cap is not None:
                self.trajectory = self.trajectory[-self.cap:]
        current = [] if anchor or stored else [kv]
        keys = torch.cat(self.trajectory + self.anchors + self.frames + current, dim=-2)
        return torch.nn.functional.scaled_dot_product_attention(query, keys[0], keys[1])


@pytest.mark.parametrize('cap', [None, 3])
def test_memory_matches_the_upstream_procedure_per_frame_and_in_blocks(cap) -> None:
    """Per-frame and multi-frame blocks both equal append-evict-attend, cap included."""
    window, per_frame, anchor = 3, 8, 2
    generator = torch.Generator().manual_seed(0)
    flags = [True, True, False, True, True, True, False, False, True, True, True, True, True,
             False, True, True, True, True, True, True, True, True]
    kvs = torch.randn(len(flags) + anchor, 2, 1, 2, per_frame, 4, generator=generator)
    queries = torch.randn(len(flags) + anchor, 1, 2, per_frame, 4, generator=generator)
    reference = _ReferenceCache(window, cap)
    expected = []
    anchor_kv = torch.cat(list(kvs[:anchor]), dim=-2)
    reference.anchors.append(anchor_kv)
    for index, flag in enumerate(flags, start=anchor):
        expected.append(reference.step(queries[index], kvs[index], False, flag))
    for blocks in ([1] * len(flags), [5, 1, 7, 2, 7], [len(flags)]):
        memory = KVMemory(1, window, SPECIAL, max_trajectory_frames=cap)
        schedule = FrameSchedule(anchor)
        plan = schedule.plan([True] * anchor)
        memory.begin(plan, per_frame, torch.device('cpu'))
        anchor_query = torch.cat(list(queries[:anchor]), dim=-2)
        memory.context(0).attend(anchor_query, anchor_kv[0], anchor_kv[1])
        memory.commit()
        schedule.commit(plan)
        outputs, first = [], 0
        for size in blocks:
            rows = range(anchor + first, anchor + first + size)
            plan = schedule.plan(flags[first:first + size])
            memory.begin(plan, per_frame, torch.device('cpu'))
            kv = torch.cat([kvs[i] for i in rows], dim=-2)
            out = memory.context(0).attend(torch.cat([queries[i] for i in rows], dim=-2),
                                           kv[0], kv[1])
            memory.commit()
            schedule.commit(plan)
            outputs.extend(out.split(per_frame, dim=-2))
            first += size
        for frame, (got, want) in enumerate(zip(outputs, expected)):
            torch.testing.assert_close(got, want, msg=f'blocks {blocks}, frame {frame}')


def test_frames_attended_per_step_for_window_w(monkeypatch) -> None:
    """Window W: a keyframe sees W keyframes (itself included), a non-keyframe W plus itself."""
    window, per_frame, anchor = 4, 10, 2
    seen = []

    def spy(query, key, value, attn_mask=None):
        seen.append(key.shape[-2] if attn_mask is None else int(attn_mask.sum()))
        return torch.zeros_like(query)

    monkeypatch.setattr('infinihand_ros.model.streaming_memory.F.scaled_dot_product_attention',
                        spy)
    memory = KVMemory(1, window, SPECIAL, max_trajectory_frames=100)
    schedule = FrameSchedule(anchor)
    _run_block(memory, schedule, [True] * anchor, per_frame, 1)
    for flag in [True] * 6 + [False]:
        _run_block(memory, schedule, [flag], per_frame, 1)
    anchors = anchor * per_frame
    keyframe_views = [anchors + min(k, window) * per_frame + SPECIAL * max(0, k - window)
                      for k in range(1, 7)]
    non_keyframe_view = anchors + (window + 1) * per_frame + SPECIAL * 2
    assert seen == [anchors] + keyframe_views + [non_keyframe_view]


def test_a_block_frame_attends_over_only_the_keys_it_sees(monkeypatch) -> None:
    """In one block each frame gets just its visible keys, as many as frame by frame, no mask."""
    window, per_frame, anchor = 4, 10, 2
    flags = [True] * 6 + [False]
    seen = {'frames': [], 'block': []}
    target = 'frames'

    def spy(query, key, value, attn_mask=None):
        assert attn_mask is None
        seen[target].append(key.shape[-2])
        return torch.zeros_like(query)

    monkeypatch.setattr('infinihand_ros.model.streaming_memory.F.scaled_dot_product_attention',
                        spy)
    for target, blocks in (('frames', [[flag] for flag in flags]), ('block', [flags])):
        memory = KVMemory(1, window, SPECIAL, max_trajectory_frames=100)
        schedule = FrameSchedule(anchor)
        _run_block(memory, schedule, [True] * anchor, per_frame, 1)
        for block in blocks:
            _run_block(memory, schedule, block, per_frame, 1)
    assert seen['block'] == seen['frames']


def test_gradients_flow_through_the_cache_across_blocks() -> None:
    """Training through two windows of one clip: writes never break backward."""
    memory = KVMemory(1, 2, SPECIAL, max_trajectory_frames=2)
    schedule = FrameSchedule(1)
    leaf = torch.randn(1, 2, 70, 4, requires_grad=True)
    total = 0.0
    for start, count in ((0, 1), (1, 3), (4, 3)):
        plan = schedule.plan([True] * count)
        memory.begin(plan, 10, torch.device('cpu'))
        tokens = leaf[..., start * 10:(start + count) * 10, :] * 2.0
        total = total + memory.context(0).attend(tokens, tokens, tokens).sum()
        memory.commit()
        schedule.commit(plan)
    total.backward()
    assert leaf.grad is not None and torch.isfinite(leaf.grad).all()
    assert leaf.grad[..., :10, :].abs().sum() > 0  # the anchor's keys were attended later


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


def test_a_non_finite_block_leaves_the_stream_as_it_was(micro_model: GeometryModel, rng) -> None:
    """Broken (NaN) weights raise ModelOutputError; restored, the stream goes on unchanged."""
    frames = _frames(rng, 4)
    broken, clean = GeometryStream(micro_model), GeometryStream(micro_model)
    with torch.no_grad():
        for stream in (broken, clean):
            stream.step(frames[:, :2])
            stream.step(frames[:, 2:3])
        tokens_before = broken.aggregator_memory.cached_tokens(0)
        weight = micro_model.aggregator.frame_blocks[0].attn.qkv.weight  # poisons the cache
        saved = weight.clone()
        weight.fill_(float('nan'))
        with pytest.raises(ModelOutputError, match='check the checkpoint'):
            broken.step(frames[:, 3:4])
        weight.copy_(saved)
        assert broken.aggregator_memory.cached_tokens(0) == tokens_before
        assert broken.schedule.frames_seen == 3
        torch.testing.assert_close(broken.step(frames[:, 3:4]).pose_encoding,
                                   clean.step(frames[:, 3:4]).pose_encoding)


def test_a_batch_of_sequences_matches_each_sequence_alone(micro_model: GeometryModel,
                                                          rng) -> None:
    """B > 1 sequences in one stream give each sequence's own outputs, windows and all."""
    first, second = _frames(rng, 5), _frames(rng, 5)
    batched = GeometryStream(micro_model)
    alone = [GeometryStream(micro_model), GeometryStream(micro_model)]
    with torch.no_grad():
        blocks = [batched.step(torch.cat((first[:, :2], second[:, :2]))),
                  batched.step(torch.cat((first[:, 2:], second[:, 2:])))]
        singles = [[stream.step(frames[:, :2]), stream.step(frames[:, 2:])]
                   for stream, frames in zip(alone, (first, second))]
    for block_index, block in enumerate(blocks):
        for sample, single in enumerate(singles):
            for name in ('pose_encoding', 'depth', 'hand_masks', 'patch_features'):
                torch.testing.assert_close(getattr(block, name)[sample:sample + 1],
                                           getattr(single[block_index], name),
                                           rtol=1e-4, atol=1e-4, msg=name)
