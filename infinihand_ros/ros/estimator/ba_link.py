"""The estimator's view of the bundle-adjustment node: is it there, and what came from it.

The BA node publishes its status periodically; each one received is a heartbeat. The link is
'waiting' before the first, 'connected' while they keep coming, and 'lost' once none came for
``timeout_s`` (the node died or hangs). Either way the estimator goes on with unrefined poses;
a node that comes back is 'connected' again and its corrections apply. Keyframe stamps the
estimator sent are remembered (bounded), so corrections of keyframes it never sent (another
estimator's stream, one before a restart) are refused. Thread-safe: heartbeats and corrections
arrive in callbacks while the inference thread reads.
"""

from collections import deque
import threading
from typing import Final

import numpy as np

WAITING: Final = 'waiting'
CONNECTED: Final = 'connected'
LOST: Final = 'lost'
#: Link states in which poses go on unrefined, and how diagnostics say so.
UNAVAILABLE: Final = {WAITING: 'not seen yet', LOST: 'lost'}


class BANodeLink:
    """Heartbeats, sent keyframe stamps and applied results of the BA node link."""

    def __init__(self, timeout_s: float, stamps_kept: int) -> None:
        """Start 'waiting'; remember the last ``stamps_kept`` keyframe stamps sent."""
        self.timeout_s = timeout_s
        self._lock = threading.Lock()
        self._last_heard_s: float | None = None
        self._node_state = 'unknown'
        self._reported = WAITING
        self._sent: deque[int] = deque(maxlen=stamps_kept)
        self._sent_set: set[int] = set()
        self.counts = {'keyframes_sent': 0, 'results_refused': 0, 'outages': 0}

    def heard(self, now_s: float, node_state: str) -> None:
        """Record a status from the BA node at ``now_s`` (its worker state)."""
        with self._lock:
            self._last_heard_s = now_s
            self._node_state = node_state

    def state(self, now_s: float) -> str:
        """Return 'waiting', 'connected' or 'lost' at ``now_s``."""
        with self._lock:
            return self._state(now_s)

    def changed(self, now_s: float) -> str | None:
        """Return the state when it differs from the last call's (None otherwise)."""
        with self._lock:
            state = self._state(now_s)
            if state == self._reported:
                return None
            if state == LOST:
                self.counts['outages'] += 1
            self._reported = state
            return state

    def sent(self, stamp_ns: int) -> None:
        """Remember a keyframe stamp sent to the BA node."""
        with self._lock:
            if len(self._sent) == self._sent.maxlen:
                self._sent_set.discard(self._sent[0])
            self._sent.append(stamp_ns)
            self._sent_set.add(stamp_ns)
            self.counts['keyframes_sent'] += 1

    def accepts(self, times_ns: np.ndarray) -> bool:
        """Return whether every stamp of a result is a keyframe this link sent (else count it)."""
        with self._lock:
            ok = all(int(stamp) in self._sent_set for stamp in times_ns)
            self.counts['results_refused'] += int(not ok)
            return ok

    def statistics(self, now_s: float) -> dict[str, object]:
        """Return the link for diagnostics: ``state``, the node's state and the counters."""
        with self._lock:
            return {'state': self._state(now_s), 'node_state': self._node_state,
                    **self.counts}

    def _state(self, now_s: float) -> str:
        """Return the state; the caller holds the lock."""
        if self._last_heard_s is None:
            return WAITING
        return CONNECTED if now_s - self._last_heard_s <= self.timeout_s else LOST
