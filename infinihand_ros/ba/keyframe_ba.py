"""Where a keyframe enters bundle adjustment: the binary keyframe pool feeding a BA worker.

Both BA backends use it: the engine's in-process one and the bundle-adjustment node. Each
keyframe enters the ``BinaryKeyframePool`` (paper Sec. 3.3); when the pool triggers, its
selection goes to the ``BundleAdjustmentWorker`` (``submit_selection`` never waits; BA runs in
its own process).
"""

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.keyframe_pool import BinaryKeyframePool
from infinihand_ros.ba.worker import BundleAdjustmentWorker

#: Keyframes of the last selection that the stream's final BA call (``finish``) overlaps.
FINISH_OVERLAP = 4


class KeyframeBA:
    """A keyframe pool and the worker its selections go to (``add`` from one thread)."""

    def __init__(self, config: BAConfig, worker: BundleAdjustmentWorker) -> None:
        """Start with an empty pool in front of ``worker``."""
        self.pool = BinaryKeyframePool(config.pool.trigger, config.pool.stride)
        self.worker = worker
        self.calls_submitted = 0

    def add(self, keyframe: KeyframeInput) -> bool:
        """Add a keyframe (its ``frame_id`` new to the pool); return whether BA was started.

        Raises:
            BAWorkerError: when the worker no longer accepts work (it gave up or was closed).

        """
        if self.pool.push(keyframe.frame_id, keyframe) is None:
            return False
        self.worker.submit_selection([entry.state for entry in self.pool.last_selection],
                                     self.pool.frame_ids())
        self.calls_submitted += 1
        return True

    def finish(self) -> bool:
        """At the end of a stream (once), refine the pool's tail: return whether a call started.

        The pool's last trigger leaves up to ``trigger`` newer keyframes no call refined; an
        offline run has no later call to wait for, so one more selection goes to the worker:
        those keyframes, after the newest ``FINISH_OVERLAP`` of the last selection (refined
        already: the oldest holds the gauge, so the tail joins what was refined before).

        Raises:
            BAWorkerError: when the worker no longer accepts work.

        """
        last = self.pool.last_selection
        newest = last[-1].state.timestamp_ns if last else None
        tail = [entry.state for entry in self.pool.entries()
                if newest is None or entry.state.timestamp_ns > newest]
        overlap = [entry.state for entry in last[-FINISH_OVERLAP:]]
        if not tail or len(overlap) + len(tail) < 2:
            return False
        self.worker.submit_selection(overlap + tail, self.pool.frame_ids())
        self.calls_submitted += 1
        return True

    def pooled_stamps(self) -> list[int]:
        """Return the stamps of the keyframes the pool holds (a later call may use them)."""
        return [entry.state.timestamp_ns for entry in self.pool.entries()]
