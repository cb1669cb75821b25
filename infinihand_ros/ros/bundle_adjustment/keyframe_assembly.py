"""Putting a keyframe's messages back together on the BA node, by stamp (no ROS types).

The estimator publishes each keyframe as several messages with one stamp; they may arrive in
any order. ``KeyframeAssembler.add`` collects them and returns the whole set once the last part
of a stamp is in. At most ``max_pending`` incomplete stamps are held: when a new stamp would
exceed that, the oldest incomplete one is dropped and counted (a part that never came).
"""

from collections import OrderedDict
from typing import Any


class KeyframeAssembler:
    """Incomplete keyframes by stamp, oldest first (not thread-safe)."""

    def __init__(self, parts: tuple[str, ...], max_pending: int) -> None:
        """Collect sets of ``parts``; hold at most ``max_pending`` incomplete stamps.

        Raises:
            ValueError: for no parts or ``max_pending`` below 1.

        """
        if not parts or max_pending < 1:
            raise ValueError(f'KeyframeAssembler: need parts and max_pending >= 1, got '
                             f'{parts!r} and {max_pending}')
        self.parts = frozenset(parts)
        self.max_pending = max_pending
        self.dropped = 0
        self._pending: OrderedDict[int, dict[str, Any]] = OrderedDict()

    def __len__(self) -> int:
        """Return the number of incomplete stamps held."""
        return len(self._pending)

    def add(self, part: str, stamp_ns: int, msg: Any) -> dict[str, Any] | None:
        """Add one part; return every part of ``stamp_ns`` when this completed the set.

        A part given twice for one stamp keeps the newer message.

        Raises:
            ValueError: for a part name that is not one of ``parts``.

        """
        if part not in self.parts:
            raise ValueError(f'KeyframeAssembler: unknown part {part!r}; expected one of '
                             f'{sorted(self.parts)}')
        collected = self._pending.setdefault(stamp_ns, {})
        collected[part] = msg
        if collected.keys() == self.parts:
            return self._pending.pop(stamp_ns)
        while len(self._pending) > self.max_pending:
            self._pending.popitem(last=False)
            self.dropped += 1
        return None

    def clear(self) -> None:
        """Forget every incomplete stamp (not counted as dropped)."""
        self._pending.clear()
