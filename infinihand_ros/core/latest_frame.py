"""A one-item mailbox between the image callback and the inference thread: latest frame wins.

``put`` never blocks: a frame still waiting is replaced (and counted as dropped), so the
inference thread always takes the newest frame and latency cannot grow under load. ``take``
waits for a frame or for ``close``.
"""

import threading
from typing import Generic, TypeVar

ItemT = TypeVar('ItemT')


class LatestFrameSlot(Generic[ItemT]):
    """Holds at most one item; thread-safe."""

    def __init__(self) -> None:
        """Start empty and open."""
        self._condition = threading.Condition()
        self._item: ItemT | None = None
        self._closed = False
        self.dropped = 0

    def put(self, item: ItemT) -> bool:
        """Store ``item``; return True when it replaced one not yet taken (a drop)."""
        with self._condition:
            replaced = self._item is not None
            self.dropped += int(replaced)
            self._item = item
            self._condition.notify()
            return replaced

    def take(self, timeout_s: float | None = None) -> ItemT | None:
        """Return the waiting item, waiting up to ``timeout_s``; None on timeout or close."""
        with self._condition:
            self._condition.wait_for(lambda: self._item is not None or self._closed, timeout_s)
            item, self._item = self._item, None
            return None if self._closed else item

    def close(self) -> None:
        """Wake every waiter; later ``take`` calls return None at once."""
        with self._condition:
            self._closed = True
            self._condition.notify_all()

    @property
    def closed(self) -> bool:
        """Return whether ``close`` was called."""
        return self._closed
