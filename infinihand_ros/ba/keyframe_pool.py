"""Binary keyframe pool of the paper's appendix C: which frames a sparse BA call refines.

The pool is a time-ordered list of entries (frame id, geometric state, bit). Every insertion
appends with bit 0; after each insertion (one frame or a whole window) the trigger is evaluated:
when the pool holds more than ``N`` entries, every ``K``-th entry starting from the oldest is
selected and handed to BA (before any bit changes), the selected bits are toggled, and every
entry whose bit is then 0 is dropped. New frames selected once are retained; retained frames
selected again are retired after that BA call.
"""

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from infinihand_ros.core.errors import InputError


@dataclass(frozen=True)
class PoolEntry:
    """One pool entry.

    Attributes:
        frame_id: the frame's identifier (e.g. its index in the stream).
        state: whatever the caller stores with the frame (image, depth, pose, ...), or None.
        bit: 1 once the frame was selected by one BA call and retained, else 0.

    """

    frame_id: int
    state: Any
    bit: int


class BinaryKeyframePool:
    """Time-ordered binary keyframe pool (paper appendix C, eq. keyframe_pool)."""

    def __init__(self, trigger: int, stride: int) -> None:
        """Create an empty pool that selects when it holds more than ``trigger`` entries.

        Args:
            trigger: N, the pool size above which a BA selection is made (>= 1).
            stride: K, every K-th entry from the oldest is selected (>= 2; with K = 1 a first
                trigger would select and retain every entry, leaving the pool above N).

        Raises:
            InputError: for a trigger below 1 or a stride below 2.

        """
        if trigger < 1:
            raise InputError(f'keyframe pool trigger N must be >= 1, got {trigger}')
        if stride < 2:
            raise InputError(f'keyframe pool stride K must be >= 2, got {stride}')
        self.trigger = trigger
        self.stride = stride
        self._entries: list[PoolEntry] = []
        self._last_selection: tuple[PoolEntry, ...] = ()

    def __len__(self) -> int:
        """Return the number of entries in the pool."""
        return len(self._entries)

    def push(self, frame_id: int, state: Any = None) -> list[int] | None:
        """Append one frame with bit 0, then evaluate the trigger.

        Returns:
            The selected frame ids, oldest first, when BA should run; otherwise None.

        """
        return self.extend([frame_id], None if state is None else [state])

    def extend(self, frame_ids: Iterable[int],
               states: Sequence[Any] | None = None) -> list[int] | None:
        """Append a window of frames (oldest first) with bit 0, then evaluate the trigger once.

        Args:
            frame_ids: ids of the new frames in time order; each must be new to the pool.
            states: one state per frame, or None to store None.

        Returns:
            The selected frame ids, oldest first, when BA should run; otherwise None.

        Raises:
            InputError: when the states do not match the ids or an id is already in the pool.

        """
        ids = [int(frame_id) for frame_id in frame_ids]
        new_states = [None] * len(ids) if states is None else list(states)
        if len(new_states) != len(ids):
            raise InputError(f'keyframe pool: {len(ids)} frame ids but {len(new_states)} states; '
                             'pass one state per frame or none')
        seen = set(self.frame_ids())
        repeated = sorted({i for i in ids if i in seen or ids.count(i) > 1})
        if repeated:
            raise InputError(f'keyframe pool: frame ids {repeated} are repeated or already in '
                             'the pool; give each frame a new id')
        self._entries.extend(PoolEntry(i, s, 0) for i, s in zip(ids, new_states))
        return self._evaluate_trigger()

    def frame_ids(self) -> list[int]:
        """Return the ids in the pool, oldest first."""
        return [entry.frame_id for entry in self._entries]

    def entries(self) -> tuple[PoolEntry, ...]:
        """Return the pool's entries, oldest first."""
        return tuple(self._entries)

    @property
    def last_selection(self) -> tuple[PoolEntry, ...]:
        """Entries handed to the most recent BA call, with their bits before the toggle."""
        return self._last_selection

    def reset(self) -> None:
        """Empty the pool (new sequence)."""
        self._entries = []
        self._last_selection = ()

    def _evaluate_trigger(self) -> list[int] | None:
        """Select, toggle and prune when the pool holds more than N entries."""
        if len(self._entries) <= self.trigger:
            return None
        selected = set(range(0, len(self._entries), self.stride))
        self._last_selection = tuple(self._entries[i] for i in sorted(selected))
        toggled = (PoolEntry(e.frame_id, e.state, e.bit ^ int(i in selected))
                   for i, e in enumerate(self._entries))
        self._entries = [entry for entry in toggled if entry.bit == 1]
        return [entry.frame_id for entry in self._last_selection]
