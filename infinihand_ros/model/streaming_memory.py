"""Streaming memory = the paper's Geometric Context Attention, as a key/value-cache policy.

Two parts with one job each:

- ``FrameSchedule`` (pure bookkeeping, shared by every memory of one stream) decides, for each
  call ("block") of S frames, which frames are anchors, which are stored, and each frame's time
  index for the 3D RoPE. The first ``anchor_frames`` frames of a sequence are anchors: a block of
  anchors attends bidirectionally among itself and is kept in full forever. After that, every
  keyframe is stored and every non-keyframe attends but is not stored.
- ``KVMemory`` holds, per layer, the cached keys/values (after qk-norm and RoPE) in three parts:
  the anchor frames in full, the most recent ``window`` keyframes in full (the pose-reference
  window; ``window=None`` keeps every keyframe) and trajectory memory (the first
  ``special_tokens`` tokens of each keyframe evicted from the window, at most
  ``max_trajectory_frames`` of them, the newest).

The window rule is LingBot-Map's: a keyframe is appended first, the window is evicted down to
``window`` keyframes, then the frame attends, so the window it sees *includes itself* (it sees
the ``window - 1`` keyframes before it). A non-keyframe sees the ``window`` stored keyframes
plus itself and is not stored. In one sentence: a frame attends to the memory as it stands right
after its own turn (anchors + window + trajectory), plus itself when it is not stored. Inside a
multi-frame block the same visibility is reproduced by giving each frame's queries only the
keys it sees (gathered, so a frame of a long block costs what it costs alone), so a block gives
the same result as its frames one by one. After a block the cached token count of each layer is
``anchor_frames * P + min(keyframes, window) * P + special_tokens * min(evicted, cap)``.

Storage does not grow with the stream: each layer owns one preallocated buffer laid out as
``[block scratch | anchors | window slots | trajectory slots]``; window and trajectory slots are
rings written in place, so a steady-state frame allocates nothing that depends on the stream's
length, and the keys a frame attends to are one contiguous slice of the buffer (attention does
not depend on key order). Capacities grow (rarely: the first anchors, the first long block, an
unbounded window or trajectory) by reallocating with doubling. A block's keys/values go to the
scratch during attention and into their slots only at ``commit()``, so a block that is not
committed (``abort()``, e.g. after a non-finite output) leaves the memory exactly as it was.
While autograd records (training), writes go to a copy of the buffer instead, so tensors saved
for backward are never overwritten.
"""

from collections.abc import Sequence
from dataclasses import dataclass

from infinihand_ros.core.errors import InputError
import torch
import torch.nn.functional as F

_NONE, _SPECIAL, _FULL = 0, 1, 2


@dataclass(frozen=True)
class BlockPlan:
    """What one call does with its S frames.

    Attributes:
        first_frame: sequence index of the block's first frame (0 = first frame of the sequence).
        is_anchor: the block consists of anchor frames (bidirectional, all stored forever).
        stored: per frame, whether it is kept in memory after the call.
        time_index: per frame, the number of frames stored before it (3D RoPE time position).
        keyframes_before: per frame, post-anchor keyframes stored before it (window bookkeeping).

    """

    first_frame: int
    is_anchor: bool
    stored: tuple[bool, ...]
    time_index: tuple[int, ...]
    keyframes_before: tuple[int, ...]

    @property
    def num_frames(self) -> int:
        """Return S, the number of frames in the block."""
        return len(self.stored)


class FrameSchedule:
    """Counts anchors, keyframes and frames of one sequence and plans each block."""

    def __init__(self, anchor_frames: int) -> None:
        """Start a sequence whose first ``anchor_frames`` frames are anchors."""
        if anchor_frames <= 0:
            raise ValueError(f'anchor_frames must be positive, got {anchor_frames}')
        self.anchor_frames = anchor_frames
        self.reset()

    def reset(self) -> None:
        """Forget the sequence: the next frame is frame 0 (an anchor)."""
        self.frames_seen = 0
        self.anchors_stored = 0
        self.keyframes_stored = 0

    @property
    def anchors_remaining(self) -> int:
        """Return how many of the next frames are still anchors."""
        return self.anchor_frames - self.anchors_stored

    def plan(self, keyframe: Sequence[bool]) -> BlockPlan:
        """Return the plan of a block whose frames carry the flags ``keyframe``.

        Anchor frames are always stored whatever their flag.

        Raises:
            InputError: for an empty block or one that mixes anchor and later frames (split it
                at ``anchors_remaining``).

        """
        count = len(keyframe)
        if count == 0:
            raise InputError('streaming block: got no frames; pass at least one frame')
        remaining = self.anchors_remaining
        if 0 < remaining < count:
            raise InputError(f'streaming block of {count} frames crosses the end of the '
                             f'{self.anchor_frames} anchor frames; pass the first {remaining} '
                             'frames in their own call')
        is_anchor = remaining > 0
        stored = (True,) * count if is_anchor else tuple(bool(flag) for flag in keyframe)
        stored_before = self.anchors_stored + self.keyframes_stored
        time_index, keyframes_before = [], []
        stored_in_block = 0
        for flag in stored:
            time_index.append(stored_before + stored_in_block)
            keyframes_before.append(self.keyframes_stored + (0 if is_anchor else stored_in_block))
            stored_in_block += int(flag)
        return BlockPlan(self.frames_seen, is_anchor, stored, tuple(time_index),
                         tuple(keyframes_before))

    def commit(self, plan: BlockPlan) -> None:
        """Advance the counters past ``plan`` (call once the block has been processed).

        Raises:
            ValueError: when ``plan`` is not the schedule's next block.

        """
        if plan.first_frame != self.frames_seen:
            raise ValueError(f'block plan starts at frame {plan.first_frame} but the schedule '
                             f'is at frame {self.frames_seen}; plan and commit blocks in order')
        self.frames_seen += plan.num_frames
        if plan.is_anchor:
            self.anchors_stored += plan.num_frames
        else:
            self.keyframes_stored += sum(plan.stored)


@dataclass
class _Region:
    """A run of frame slots in a layer buffer: ``capacity`` slots of ``tokens`` tokens each."""

    start: int = 0
    capacity: int = 0
    tokens: int = 0

    @property
    def end(self) -> int:
        return self.start + self.capacity * self.tokens

    def slot(self, index: int) -> slice:
        """Return the token range of slot ``index``."""
        first = self.start + index * self.tokens
        return slice(first, first + self.tokens)


@dataclass
class _Ring:
    """Frame slots filled in order, then overwritten oldest first; each holds a keyframe order."""

    orders: list[int]
    limit: int | None
    next_slot: int = 0

    @property
    def filled(self) -> int:
        return len(self.orders)

    @property
    def full(self) -> bool:
        return self.limit is not None and self.filled >= self.limit

    def target(self) -> int:
        """Return the slot the next entry goes to (the oldest one when full)."""
        return self.next_slot if self.full else self.filled

    def put(self, order: int) -> int:
        """Record an entry of keyframe ``order``; return its slot."""
        slot = self.target()
        if self.full:
            self.orders[slot] = order
            self.next_slot = (slot + 1) % self.limit
        else:
            self.orders.append(order)
        return slot

    def oldest(self) -> int:
        """Return the slot of the oldest entry."""
        return self.next_slot if self.full else 0


@dataclass(frozen=True)
class _Copy:
    """One copy of tokens inside a layer buffer (source and target token ranges)."""

    source: slice
    target: slice


class _LayerContext:
    """Attention of one layer's current tokens over its cache (see ``AttentionContext``)."""

    def __init__(self, memory: 'KVMemory', layer: int) -> None:
        self._memory = memory
        self._layer = layer

    def attend(self, query: torch.Tensor, key: torch.Tensor, value: torch.Tensor
               ) -> torch.Tensor:
        """Return attention of (B, H, S*P, D) queries over cached + current keys/values."""
        return self._memory.attend(self._layer, query, key, value)


class KVMemory:
    """Per-layer key/value cache with the anchor / window / trajectory policy.

    Use per block: ``begin(plan, P)``, then each layer attends through ``context(layer)``, then
    ``commit()`` stores the block's keys/values and evicts frames beyond the window (or
    ``abort()`` forgets the block).
    """

    def __init__(self, num_layers: int, window: int | None, special_tokens: int,
                 max_trajectory_frames: int | None = None) -> None:
        """Build an empty memory for ``num_layers`` layers.

        Args:
            num_layers: attention layers sharing this policy.
            window: keyframes kept in full, the current keyframe included (LingBot-Map's
                ``kv_cache_sliding_window``), or None to keep every keyframe.
            special_tokens: leading tokens of each frame kept as trajectory memory on eviction
                (clipped to the tokens per frame).
            max_trajectory_frames: trajectory memory keeps the newest this-many evicted frames,
                or None for no limit. This bounds memory and attention cost over arbitrarily
                long streams.

        Raises:
            ValueError: for a window or trajectory limit below 1.

        """
        for name, limit in (('window', window), ('max_trajectory_frames', max_trajectory_frames)):
            if limit is not None and limit < 1:
                raise ValueError(f'KVMemory: {name} must be >= 1 or None, got {limit}')
        self.num_layers = num_layers
        self.window = window
        self.special_tokens = special_tokens
        self.max_trajectory_frames = max_trajectory_frames
        self.reset()

    def reset(self) -> None:
        """Drop every cached token (start of a new sequence)."""
        self._data: list[torch.Tensor | None] = [None] * self.num_layers
        self._scratch = _Region()
        self._anchors = _Region()
        self._window_slots = _Region()
        self._trajectory_slots = _Region()
        self._anchor_count = 0
        self._window = _Ring([], self.window)
        self._trajectory = _Ring([], self.max_trajectory_frames)
        self._plan: BlockPlan | None = None
        self._attended: list[bool] = []
        self._key_range = slice(0, 0)
        self._frame_keys: list[torch.Tensor | None] = []
        self.tokens_per_frame = 0
        self._reallocations = 0

    def cached_tokens(self, layer: int) -> int:
        """Return the number of cached tokens of ``layer`` (the same for every layer)."""
        del layer
        return (self._anchor_count * self._anchors.tokens
                + self._window.filled * self._window_slots.tokens
                + self._trajectory.filled * self._trajectory_slots.tokens)

    @property
    def reallocations(self) -> int:
        """Return how often the buffers were reallocated to grow (0 in a steady state)."""
        return self._reallocations

    def allocated_tokens(self) -> int:
        """Return the token capacity of each layer's buffer (bounded for bounded settings)."""
        return self._trajectory_slots.end

    def begin(self, plan: BlockPlan, tokens_per_frame: int, device: torch.device) -> None:
        """Prepare attention for the block ``plan`` with P = ``tokens_per_frame`` tokens/frame.

        Raises:
            ValueError: when the tokens per frame differ from earlier blocks of the sequence.

        """
        if self.tokens_per_frame not in (0, tokens_per_frame):
            raise ValueError(f'KVMemory: {tokens_per_frame} tokens per frame, but the sequence '
                             f'started with {self.tokens_per_frame}; reset() between sequences '
                             'of different image sizes')
        self.tokens_per_frame = tokens_per_frame
        self._plan = plan
        self._layout(plan, tokens_per_frame)
        block_start = self._scratch.end - plan.num_frames * tokens_per_frame
        if plan.is_anchor:
            self._key_range = slice(block_start, self._anchors.slot(self._anchor_count).start)
            self._frame_keys = []
        else:
            self._key_range = slice(block_start, self._cache_end())
            self._frame_keys = self._block_keys(plan, device)
        self._attended = [False] * self.num_layers

    def keys_per_query_frame(self, frames: int) -> list[int]:
        """Return how many keys each of the current block's ``frames`` query frames attends over.

        The memory it sees plus its own block's keys (for profiling).
        """
        every = self._key_range.stop - self._key_range.start
        visible = self._frame_keys or [None] * frames
        return [every if keys is None else len(keys) for keys in visible]

    def context(self, layer: int) -> _LayerContext:
        """Return the attention context of ``layer`` for the current block."""
        if self._plan is None:
            raise RuntimeError('KVMemory.context called before begin(plan, ...)')
        return _LayerContext(self, layer)

    def attend(self, layer: int, query: torch.Tensor, key: torch.Tensor, value: torch.Tensor
               ) -> torch.Tensor:
        """Put the block's keys/values of ``layer`` in the scratch and attend over the cache."""
        if self._plan is None:
            raise RuntimeError('KVMemory.attend called before begin(plan, ...)')
        data = self._buffer(layer, key)
        data = self._write(layer, data, slice(self._key_range.start, self._scratch.end),
                           torch.stack((key, value)))
        self._attended[layer] = True
        keys, values = data[0, ..., self._key_range, :], data[1, ..., self._key_range, :]
        if all(visible is None for visible in self._frame_keys):
            return F.scaled_dot_product_attention(query, keys, values)
        per_frame = self.tokens_per_frame
        outputs = []
        for frame, visible in enumerate(self._frame_keys):
            rows = slice(frame * per_frame, (frame + 1) * per_frame)
            frame_keys, frame_values = ((keys, values) if visible is None else
                                        (keys.index_select(-2, visible),
                                         values.index_select(-2, visible)))
            outputs.append(F.scaled_dot_product_attention(query[..., rows, :], frame_keys,
                                                          frame_values))
        return torch.cat(outputs, dim=-2)

    def commit(self) -> None:
        """Store the current block's stored frames, evicting beyond the window, frame by frame."""
        plan = self._plan
        if plan is None:
            raise RuntimeError('KVMemory.commit called before begin(plan, ...)')
        if not all(self._attended):
            raise RuntimeError('KVMemory.commit: a layer did not attend during the block')
        copies = self._commit_copies(plan)
        for layer in range(self.num_layers):
            data = self._data[layer]
            for copy in copies:
                data = self._write(layer, data, copy.target, data[..., copy.source, :])
        if plan.is_anchor:
            self._anchor_count += plan.num_frames
        else:
            for order, stored in zip(plan.keyframes_before, plan.stored):
                if stored:
                    if self._window.full:
                        self._trajectory.put(self._window.orders[self._window.oldest()])
                    self._window.put(order)
        self.abort()

    def abort(self) -> None:
        """Forget the current block without storing it (the memory stays as before ``begin``)."""
        self._plan = None
        self._frame_keys = []

    # Layout and storage.

    def _layout(self, plan: BlockPlan, per_frame: int) -> None:
        """Grow the regions the block needs (rare: reallocates and keeps the cached tokens)."""
        special = min(self.special_tokens, per_frame)
        count = plan.num_frames
        anchors = self._anchor_count + count if plan.is_anchor else self._anchor_count
        window = self._window.filled + (0 if plan.is_anchor else sum(plan.stored))
        trajectory = self._trajectory.filled + max(0, window - (self.window or window))
        needed = (max(count, self._scratch.capacity), max(anchors, self._anchors.capacity),
                  self._capped(window, self._window_slots.capacity, self.window),
                  self._capped(trajectory, self._trajectory_slots.capacity,
                               self.max_trajectory_frames))
        current = (self._scratch.capacity, self._anchors.capacity,
                   self._window_slots.capacity, self._trajectory_slots.capacity)
        if needed == current and self._scratch.tokens == per_frame:
            return
        old = (self._scratch, self._anchors, self._window_slots, self._trajectory_slots)
        start = 0
        regions = []
        for capacity, tokens in zip(needed, (per_frame, per_frame, per_frame, special)):
            regions.append(_Region(start, capacity, tokens))
            start += capacity * tokens
        self._scratch, self._anchors, self._window_slots, self._trajectory_slots = regions
        if self._data[0] is not None:
            self._reallocations += 1
        self._data = [None if data is None else self._moved(data, old, regions)
                      for data in self._data]

    @staticmethod
    def _capped(needed: int, capacity: int, limit: int | None) -> int:
        """Return the capacity for ``needed`` slots: doubling growth, never above ``limit``."""
        if needed <= capacity:
            return capacity
        grown = max(needed, 2 * capacity)
        return grown if limit is None else min(grown, limit)

    @staticmethod
    def _moved(data: torch.Tensor, old: tuple[_Region, ...], new: list[_Region]
               ) -> torch.Tensor:
        """Return a buffer with the new layout holding ``data``'s slots (scratch not kept)."""
        moved = data.new_zeros(*data.shape[:-2], new[-1].end, data.shape[-1])
        for before, after in zip(old[1:], new[1:]):
            length = before.capacity * before.tokens
            moved[..., after.start:after.start + length, :] = \
                data[..., before.start:before.end, :]
        return moved

    def _buffer(self, layer: int, key: torch.Tensor) -> torch.Tensor:
        """Return the layer's buffer, allocated on first use with the keys' shape and dtype."""
        data = self._data[layer]
        if data is None:
            data = key.new_zeros(2, *key.shape[:-2], self._trajectory_slots.end, key.shape[-1])
            self._data[layer] = data
        elif data.shape[1:3] != key.shape[:2] or data.dtype != key.dtype:
            raise ValueError(f'KVMemory: keys of batch/heads {tuple(key.shape[:2])} and '
                             f'{key.dtype} after a sequence started with '
                             f'{tuple(data.shape[1:3])} and {data.dtype}; reset() first')
        return data

    def _write(self, layer: int, data: torch.Tensor, target: slice, tokens: torch.Tensor
               ) -> torch.Tensor:
        """Write ``tokens`` into ``target`` of the layer's buffer; return the buffer."""
        if torch.is_grad_enabled() and (tokens.requires_grad or data.requires_grad):
            data = data.clone()  # tensors saved for backward keep the old values
        data[..., target, :] = tokens
        self._data[layer] = data
        return data

    # Planning.

    def _cache_end(self) -> int:
        """Return the end of the filled cache (window, then trajectory, both filled in order)."""
        if self._trajectory.filled:
            return self._trajectory_slots.start + self._trajectory.filled \
                * self._trajectory_slots.tokens
        return self._window_slots.start + self._window.filled * self._window_slots.tokens

    def _commit_copies(self, plan: BlockPlan) -> list[_Copy]:
        """Return the copies from the scratch into anchor/window/trajectory slots, in order."""
        per_frame = self.tokens_per_frame
        block_start = self._scratch.end - plan.num_frames * per_frame

        def frame_tokens(frame: int) -> slice:
            return slice(block_start + frame * per_frame, block_start + (frame + 1) * per_frame)

        if plan.is_anchor:
            return [_Copy(frame_tokens(frame), self._anchors.slot(self._anchor_count + frame))
                    for frame in range(plan.num_frames)]
        window = _Ring(list(self._window.orders), self.window, self._window.next_slot)
        trajectory = _Ring(list(self._trajectory.orders), self.max_trajectory_frames,
                           self._trajectory.next_slot)
        special = self._trajectory_slots.tokens
        copies = []
        for frame, (order, stored) in enumerate(zip(plan.keyframes_before, plan.stored)):
            if not stored:
                continue
            if window.full:
                oldest = window.oldest()
                evicted = self._window_slots.slot(oldest)
                target = self._trajectory_slots.slot(trajectory.put(window.orders[oldest]))
                copies.append(_Copy(slice(evicted.start, evicted.start + special), target))
            copies.append(_Copy(frame_tokens(frame), self._window_slots.slot(window.put(order))))
        return copies

    def _block_keys(self, plan: BlockPlan, device: torch.device) -> list[torch.Tensor | None]:
        """Return per block frame the indices of the keys it sees (None: all of them).

        This reproduces frame-by-frame streaming: frame j, after whose turn ``K_j`` keyframes
        are stored, sees a keyframe of order ``o`` in full when ``o >= K_j - window``, only its
        special tokens when it has been evicted but is among the newest
        ``max_trajectory_frames`` evicted, and nothing otherwise; anchors always, later or
        unstored block frames never, itself in full.
        """
        count, per_frame = plan.num_frames, self.tokens_per_frame
        special = self._trajectory_slots.tokens
        orders = torch.tensor(plan.keyframes_before, dtype=torch.long, device=device)
        stored = torch.tensor(plan.stored, dtype=torch.bool, device=device)
        after = orders + stored.long()
        unbounded = torch.full_like(after, torch.iinfo(torch.long).min // 2)
        lowest_full = unbounded if self.window is None else after - self.window
        lowest_special = (unbounded if self.max_trajectory_frames is None
                          else lowest_full - self.max_trajectory_frames)

        def codes_for(slot_orders: list[int] | torch.Tensor) -> torch.Tensor:
            slot_orders = torch.as_tensor(slot_orders, dtype=torch.long, device=device)
            full = slot_orders[None] >= lowest_full[:, None]
            kept = slot_orders[None] >= lowest_special[:, None]
            return torch.where(full, _FULL, torch.where(kept, _SPECIAL, _NONE))

        index = torch.arange(count, device=device)
        block_codes = torch.where((index[None] < index[:, None]) & stored[None],
                                  codes_for(orders), _NONE)
        block_codes[index, index] = _FULL
        codes = torch.cat((block_codes, codes_for(self._window.orders)), dim=1)[..., None]
        is_special = torch.arange(per_frame, device=device) < special
        frames = ((codes == _FULL) | ((codes == _SPECIAL) & is_special)).flatten(1)
        trajectory = (codes_for(self._trajectory.orders) != _NONE).repeat_interleave(special, 1)
        anchors = torch.ones(count, self._anchor_count * per_frame, dtype=torch.bool,
                             device=device)
        block, window = frames.split((count * per_frame, frames.shape[1] - count * per_frame), 1)
        visible = torch.cat((block, anchors, window, trajectory), dim=1)
        return [None if bool(row.all()) else row.nonzero().squeeze(1) for row in visible]
