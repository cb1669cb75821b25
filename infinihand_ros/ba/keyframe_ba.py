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

    def pooled_stamps(self) -> list[int]:
        """Return the stamps of the keyframes the pool holds (a later call may use them)."""
        return [entry.state.timestamp_ns for entry in self.pool.entries()]
