"""Streaming memory = the paper's Geometric Context Attention, as a key/value-cache policy.

Two parts with one job each:

- ``FrameSchedule`` (pure bookkeeping, shared by every memory of one stream) decides, for each
  call ("block") of S frames, which frames are anchors, which are stored, and each frame's time
  index for the 3D RoPE. The first ``anchor_frames`` frames of a sequence are anchors: a block of
  anchors attends bidirectionally among itself and is kept in full forever. After that, every
  keyframe is stored and every non-keyframe attends but is not stored.
- ``KVMemory`` holds, per layer, the cached keys/values (after qk-norm and RoPE) in three parts:
  trajectory memory (the ``special_tokens`` first tokens of each keyframe evicted from the window),
  the anchor frames in full, and the most recent ``window`` keyframes in full (``window=None``
  keeps every keyframe, as the camera head's causal cache does).

A frame attends to trajectory + anchors + the window as it stands after all earlier frames +
itself. Inside a multi-frame block, frame j sees block frame i < j only if i is stored, and only
its special tokens if i (or an older window frame) would have left the window before j. So a
block gives the same result as its frames one by one. The cached token count of each layer is
``anchor_frames * P + min(keyframes, window) * P + special_tokens * evicted``.
"""

from collections import deque
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


class _TokenBuffer:
    """Append-only (2, B, heads, n, D) key/value tokens with amortised growth."""

    def __init__(self) -> None:
        self.data: torch.Tensor | None = None
        self.length = 0

    def append(self, kv: torch.Tensor) -> None:
        needed = self.length + kv.shape[-2]
        if self.data is None or needed > self.data.shape[-2]:
            capacity = max(needed, 2 * (0 if self.data is None else self.data.shape[-2]))
            grown = kv.new_empty(*kv.shape[:-2], capacity, kv.shape[-1])
            if self.data is not None:
                grown[..., :self.length, :] = self.view()
            self.data = grown
        self.data[..., self.length:needed, :] = kv
        self.length = needed

    def view(self) -> torch.Tensor | None:
        return None if self.data is None else self.data[..., :self.length, :]

    def keep_last(self, count: int) -> None:
        """Drop all but the newest ``count`` tokens."""
        if self.data is not None and self.length > count:
            self.data[..., :count, :] = self.data[..., self.length - count:self.length, :].clone()
            self.length = count


class _LayerStore:
    """Cached keys/values of one layer: trajectory, anchors and window, each (2, B, H, n, D)."""

    def __init__(self) -> None:
        self.trajectory = _TokenBuffer()
        self.anchors: list[torch.Tensor] = []
        self.window: deque[torch.Tensor] = deque()
        self.pending: torch.Tensor | None = None

    def parts(self) -> list[torch.Tensor]:
        trajectory = self.trajectory.view()
        return ([] if trajectory is None else [trajectory]) + self.anchors + list(self.window)

    def num_tokens(self) -> int:
        return sum(part.shape[-2] for part in self.parts())


class _LayerContext:
    """Attention of one layer's current tokens over its cache (see ``AttentionContext``)."""

    def __init__(self, memory: 'KVMemory', store: _LayerStore) -> None:
        self._memory = memory
        self._store = store

    def attend(self, query: torch.Tensor, key: torch.Tensor, value: torch.Tensor
               ) -> torch.Tensor:
        """Return attention of (B, H, S*P, D) queries over cached + current keys/values."""
        parts = self._store.parts()
        self._store.pending = torch.stack((key, value))
        keys = torch.cat([part[0] for part in parts] + [key], dim=-2)
        values = torch.cat([part[1] for part in parts] + [value], dim=-2)
        masks = self._memory.block_masks
        if masks is None:
            return F.scaled_dot_product_attention(query, keys, values)
        cached = keys.shape[-2] - key.shape[-2]
        per_frame = self._memory.tokens_per_frame
        outputs = []
        for frame, mask in enumerate(masks):
            end = cached + (frame + 1) * per_frame
            visible = mask[:end]
            outputs.append(F.scaled_dot_product_attention(
                query[..., frame * per_frame:(frame + 1) * per_frame, :], keys[..., :end, :],
                values[..., :end, :], attn_mask=None if bool(visible.all()) else visible[None]))
        return torch.cat(outputs, dim=-2)


class KVMemory:
    """Per-layer key/value cache with the anchor / window / trajectory policy.

    Use per block: ``begin(plan, P)``, then each layer attends through ``context(layer)``, then
    ``commit()`` stores the block's keys/values and evicts frames beyond the window.
    """

    def __init__(self, num_layers: int, window: int | None, special_tokens: int,
                 max_trajectory_frames: int | None = None) -> None:
        """Build an empty memory for ``num_layers`` layers.

        Args:
            num_layers: attention layers sharing this policy.
            window: keyframes kept in full, or None to keep every keyframe.
            special_tokens: leading tokens of each frame kept as trajectory memory on eviction.
            max_trajectory_frames: trajectory memory keeps at most this many evicted frames
                (the newest; up to a quarter more between trims), or None for no limit. This
                bounds memory and attention cost over arbitrarily long streams.

        """
        self.num_layers = num_layers
        self.window = window
        self.special_tokens = special_tokens
        self.max_trajectory_frames = max_trajectory_frames
        self.reset()

    def reset(self) -> None:
        """Drop every cached token (start of a new sequence)."""
        self._stores = [_LayerStore() for _ in range(self.num_layers)]
        self._plan: BlockPlan | None = None
        self._window_orders: deque[int] = deque()
        self.block_masks: torch.Tensor | None = None
        self.tokens_per_frame = 0

    def cached_tokens(self, layer: int) -> int:
        """Return the number of cached tokens of ``layer``."""
        return self._stores[layer].num_tokens()

    def begin(self, plan: BlockPlan, tokens_per_frame: int, device: torch.device) -> None:
        """Prepare attention for the block ``plan`` with P = ``tokens_per_frame`` tokens/frame."""
        self._plan = plan
        self.tokens_per_frame = tokens_per_frame
        self.block_masks = self._build_masks(plan, tokens_per_frame, device)

    def context(self, layer: int) -> _LayerContext:
        """Return the attention context of ``layer`` for the current block."""
        if self._plan is None:
            raise RuntimeError('KVMemory.context called before begin(plan, ...)')
        return _LayerContext(self, self._stores[layer])

    def commit(self) -> None:
        """Store the current block's keys/values and evict window frames beyond ``window``."""
        plan, per_frame = self._plan, self.tokens_per_frame
        if plan is None:
            raise RuntimeError('KVMemory.commit called before begin(plan, ...)')
        for store in self._stores:
            if store.pending is None:
                raise RuntimeError('KVMemory.commit: a layer did not attend during the block')
            if plan.is_anchor:
                store.anchors.append(store.pending)
            else:
                for frame, stored in enumerate(plan.stored):
                    if stored:
                        store.window.append(store.pending[..., frame * per_frame:
                                                          (frame + 1) * per_frame, :].clone())
                self._evict(store)
            store.pending = None
        if not plan.is_anchor:
            self._window_orders.extend(order for order, stored in
                                       zip(plan.keyframes_before, plan.stored) if stored)
            while self.window is not None and len(self._window_orders) > self.window:
                self._window_orders.popleft()
        self._plan = None
        self.block_masks = None

    def _evict(self, store: _LayerStore) -> None:
        """Move the oldest window frames' special tokens to trajectory memory."""
        while self.window is not None and len(store.window) > self.window:
            kept = store.window.popleft()[..., :self.special_tokens, :]
            store.trajectory.append(kept)
            if self.max_trajectory_frames is not None:
                limit = self.max_trajectory_frames * kept.shape[-2]
                if store.trajectory.length > limit + limit // 4:
                    store.trajectory.keep_last(limit)

    def _build_masks(self, plan: BlockPlan, per_frame: int, device: torch.device
                     ) -> torch.Tensor | None:
        """Return (S, L) key visibility per query frame, or None when every key is visible."""
        if plan.is_anchor or plan.num_frames == 1:
            return None
        count = plan.num_frames
        store = self._stores[0]
        trajectory = store.trajectory.length
        anchor_frames = sum(part.shape[-2] for part in store.anchors) // per_frame
        window_orders = torch.tensor(list(self._window_orders), dtype=torch.long, device=device)
        block_orders = torch.tensor(plan.keyframes_before, dtype=torch.long, device=device)
        stored = torch.tensor(plan.stored, dtype=torch.bool, device=device)
        if self.window is None:
            lowest = torch.full((count, 1), -1, dtype=torch.long, device=device)
        else:
            lowest = (block_orders - self.window)[:, None]
        window_codes = torch.where(window_orders[None] >= lowest, _FULL, _SPECIAL)
        index = torch.arange(count, device=device)
        earlier = (index[None] < index[:, None]) & stored[None]
        block_codes = torch.where(earlier & (block_orders[None] >= lowest), _FULL,
                                  torch.where(earlier, _SPECIAL, _NONE))
        block_codes[index, index] = _FULL
        codes = torch.cat((torch.full((count, anchor_frames), _FULL, device=device),
                           window_codes.expand(count, -1), block_codes), dim=1)
        is_special = torch.arange(per_frame, device=device) < self.special_tokens
        visible = (codes[..., None] == _FULL) | ((codes[..., None] == _SPECIAL) & is_special)
        return torch.cat((torch.ones(count, trajectory, dtype=torch.bool, device=device),
                          visible.flatten(1)), dim=1)
