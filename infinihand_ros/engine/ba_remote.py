"""Bundle adjustment in another process the caller talks to (the bundle-adjustment node).

The ``BABackend`` for ``engine.bundle_adjustment: node``: the engine offers keyframes exactly as
to its in-process backend; they wait in a bounded outbox until the caller's transport takes
them (``take_keyframes``, after each push) and sends them. The transport hands back each BA
result as ``Corrections`` (``receive``, from any thread); the engine folds them into the pose
track before the next frame is posed, or when the caller asks between frames
(``StreamingEngine.fold_in_ba``). The remote BA is never waited for. Its failed calls are not
known here: the node publishes corrections of successful calls only, and its status counts
failures without naming their frames.
"""

from collections import deque
import threading
from typing import Final

from infinihand_ros.ba.corrections import Corrections
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.engine.ba_backend import prune_corrections
from infinihand_ros.engine.pose_track import PoseTrack
import numpy as np

#: Keyframes kept for a transport that does not take them (oldest dropped first).
OUTBOX_SIZE: Final = 16


class RemoteBA:
    """Keyframes out and corrections in, for a transport the caller owns (thread-safe)."""

    def __init__(self, outbox_size: int = OUTBOX_SIZE) -> None:
        """Start with nothing to send and nothing received."""
        self._lock = threading.Lock()
        self._outbox: deque[KeyframeInput] = deque(maxlen=outbox_size)
        self._inbox: deque[Corrections] = deque()
        self.counts = {'offered': 0, 'received': 0, 'folded_in': 0}

    def offer(self, keyframe: KeyframeInput) -> None:
        """Queue a keyframe for the transport (never waits)."""
        with self._lock:
            self._outbox.append(keyframe)
            self.counts['offered'] += 1

    def take_keyframes(self) -> list[KeyframeInput]:
        """Return the keyframes offered since the last call, oldest first (the transport's)."""
        with self._lock:
            taken = list(self._outbox)
            self._outbox.clear()
            return taken

    def receive(self, corrections: Corrections) -> None:
        """Queue one BA result for the pose track (from any thread)."""
        with self._lock:
            self._inbox.append(corrections)
            self.counts['received'] += 1

    def fold_in(self, track: PoseTrack) -> None:
        """Apply every received result to ``track``; prune what no frame can query.

        A correction ``D`` maps a keyframe's submitted (scaled raw) pose onto its refined one,
        so it is handed over as refined ``D`` over submitted identity.
        """
        with self._lock:
            received = list(self._inbox)
            self._inbox.clear()
        for corrections in received:
            identity = np.broadcast_to(np.eye(4), np.shape(corrections.corrections))
            track.update_corrections(np.asarray(corrections.times_ns),
                                     np.asarray(corrections.corrections), identity)
            self.counts['folded_in'] += 1
        if received:
            prune_corrections(track, [])

    def settle(self, track: PoseTrack, timeout_s: float | None = None) -> bool:
        """Fold in what was received; the remote BA is not waited for (returns True)."""
        self.fold_in(track)
        return True

    def failed_frames(self) -> frozenset[int]:
        """Return no frames: the BA node's messages do not name the frames of failed calls."""
        return frozenset()

    def episode_refined(self) -> bool:
        """Return False: the BA node refines windows of the stream, never the whole episode."""
        return False

    def statistics(self) -> dict[str, object]:
        """Return the counters (the transport reports the link's state)."""
        with self._lock:
            return {'state': 'remote', **self.counts}

    def reset(self) -> None:
        """Drop keyframes not yet sent and results not yet folded in."""
        with self._lock:
            self._outbox.clear()
            self._inbox.clear()

    def close(self) -> None:
        """Nothing runs here; the transport is the caller's."""
