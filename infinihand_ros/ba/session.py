"""The bundle-adjustment node's sequences: keyframes that come as messages into ``KeyframeBA``.

Each keyframe enters ``KeyframeBA`` (the binary pool and its BA worker, as in the engine's
in-process backend). Each finished call becomes ``Corrections`` (``D = T_refined @
T_submitted^-1`` per keyframe) for the result callback, and the refined poses are kept
(bounded, by stamp) for the refined path. A keyframe older than the last one, or newer by more
than ``max_gap_ns``, starts a new sequence (a restarted estimator: another world frame): new
pool, new worker, the old worker's results ignored. A worker that gave up (its BA process kept
dying) is replaced the same way.
"""

from collections import OrderedDict
from collections.abc import Callable
import logging
import threading

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.corrections import Corrections
from infinihand_ros.ba.corrections import keyframe_corrections
from infinihand_ros.ba.keyframe import BAOutput
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.keyframe_ba import KeyframeBA
from infinihand_ros.ba.worker import BAWorkerError
from infinihand_ros.ba.worker import BundleAdjustmentWorker
import numpy as np

logger = logging.getLogger(__name__)

#: Builds a worker that sends each result to the callback (``BundleAdjustmentWorker``).
WorkerFactory = Callable[[BAConfig, Callable[[BAOutput], None]], BundleAdjustmentWorker]
ResultCallback = Callable[[Corrections], None]


class BundleAdjustmentSession:
    """Pool, worker and refined poses of the current sequence (``add`` from one thread)."""

    def __init__(self, config: BAConfig, max_gap_ns: int, path_length: int,
                 on_result: ResultCallback,
                 worker_factory: WorkerFactory = BundleAdjustmentWorker) -> None:
        """Start the first sequence (its worker starts its BA process in the background)."""
        self.config = config
        self.max_gap_ns = max_gap_ns
        self.path_length = path_length
        self._on_result = on_result
        self._factory = worker_factory
        self._lock = threading.Lock()
        self._refined: OrderedDict[int, np.ndarray] = OrderedDict()  # stamp -> (4, 4)
        self.keyframes = 0
        self.sequences = 0
        self._start()

    @property
    def worker(self) -> BundleAdjustmentWorker:
        """Return the current sequence's worker."""
        return self._ba.worker

    def add(self, keyframe: KeyframeInput) -> bool:
        """Add a keyframe (its ``frame_id`` new to the session); return whether BA was started."""
        stamp = keyframe.timestamp_ns
        if self._last_stamp is not None and not (
                0 < stamp - self._last_stamp <= self.max_gap_ns):
            logger.info('keyframe stamp %d after %d: new sequence', stamp, self._last_stamp)
            self._restart()
        self._last_stamp = stamp
        self.keyframes += 1
        try:
            return self._ba.add(keyframe)
        except BAWorkerError as exc:
            logger.error('BA worker failed (%s); its selection is dropped and a new sequence '
                         'starts', exc)
            self._restart()
            return False

    def refined_poses(self) -> list[tuple[int, np.ndarray]]:
        """Return (stamp, refined ``T_world_cam`` (4, 4)) of the sequence, oldest first."""
        with self._lock:
            return list(self._refined.items())

    def close(self, timeout_s: float | None) -> None:
        """Stop the worker (a running call gets ``timeout_s``; None waits for all)."""
        self._ba.worker.close(timeout_s)

    def _start(self) -> None:
        """Start a sequence: empty pool, no refined poses, a new worker."""
        self.sequences += 1
        sequence = self.sequences
        self._last_stamp: int | None = None
        with self._lock:
            self._refined.clear()
        worker = self._factory(self.config, lambda output: self._finished(sequence, output))
        self._ba = KeyframeBA(self.config, worker)

    def _restart(self) -> None:
        """End the sequence at once (a running call is abandoned) and start a new one."""
        self._ba.worker.close(0.0)
        self._start()

    def _finished(self, sequence: int, output: BAOutput) -> None:
        """Keep a finished call's refined poses and hand on its corrections (worker thread)."""
        with self._lock:
            if sequence != self.sequences:
                return
            for stamp, pose in zip(output.timestamps_ns, output.T_world_cam_refined):
                self._refined.pop(int(stamp), None)
                self._refined[int(stamp)] = pose
            self._refined = OrderedDict(sorted(self._refined.items()))
            while len(self._refined) > self.path_length:
                self._refined.popitem(last=False)
        self._on_result(Corrections(np.asarray(output.timestamps_ns, dtype=np.int64),
                                    keyframe_corrections(output.T_world_cam_refined,
                                                         output.T_world_cam_raw)))
