"""The geometry branch a frame owes after its result went out first (``Route.TRACKED_FIRST``).

Without BA, a frame due for the geometry branch while the tracker holds the camera is tracked
from the image first and its result goes out at once; the geometry branch then runs on it in
``catch_up()`` (a live caller's idle time after publishing) or at the start of the next call,
and the pose track takes its outputs before the next frame. With ``geometry_lag: n`` (n >= 1)
they come n frames later: the next n frames are tracked from the image too, and they are taken
in before the frame after those (or before a frame that needs them first: the tracker lost the
camera, the metric scale still warms up); ``catch_up()`` then starts the branch in a worker
thread, paused at block boundaries whenever a frame is being pushed (``WorkerGate``), so the
next frames' answers do not wait for it. Results do not depend on when it runs.

``DeferredGeometry`` keeps this bookkeeping (at most one frame owed, its worker thread); the
engine owns one, gives it the function that runs the geometry branch on a frame and takes the
outputs in itself.
"""

from collections.abc import Callable
from collections.abc import Iterator
from collections.abc import Sequence
from concurrent.futures import Future
from concurrent.futures import ThreadPoolExecutor
import contextlib
import dataclasses
import threading
import time

from infinihand_ros.core.errors import ModelOutputError
from infinihand_ros.engine.camera_space import CameraSpaceFrame
from infinihand_ros.engine.camera_space import PreparedFrame
from infinihand_ros.engine.camera_tracker import TrackerMoment
import torch


@dataclasses.dataclass
class OwedFrame:
    """A frame whose result went out before its geometry branch ran.

    Attributes:
        record: its record without geometry (hands, tracking view).
        moment: the tracker right after the frame, None until the frame is finished.
        run: its geometry branch in the worker thread (``catch_up``), None until started.

    """

    record: CameraSpaceFrame
    moment: TrackerMoment | None = None
    run: Future | None = None


class WorkerGate:
    """Holds the geometry worker at block boundaries while a frame is being pushed."""

    def __init__(self) -> None:
        """Start open, with no worker thread known."""
        self._condition = threading.Condition()
        self._callers = 0
        self.worker: int | None = None  # the worker thread's ident
        self.waited_s = 0.0  # seconds the worker has waited here, in all

    @contextlib.contextmanager
    def closed(self) -> Iterator[None]:
        """Hold the worker at its next boundary while inside."""
        with self._condition:
            self._callers += 1
        try:
            yield
        finally:
            with self._condition:
                self._callers -= 1
                self._condition.notify_all()

    def boundary(self, *unused: object) -> None:
        """Wait here, in the worker thread, until no caller is inside (a forward pre-hook)."""
        if threading.get_ident() != self.worker:
            return
        start = time.perf_counter()
        with self._condition:
            self._condition.wait_for(lambda: self._callers == 0)
        self.waited_s += time.perf_counter() - start


class DeferredGeometry:
    """At most one frame's owed geometry branch: when it is due, where it runs, its outcome."""

    def __init__(self, run: Callable[[PreparedFrame], CameraSpaceFrame],
                 boundaries: Callable[[], Sequence[torch.nn.Module]], lag: int,
                 cost: Callable[[float], None]) -> None:
        """Keep how the geometry branch runs; nothing is owed yet.

        Args:
            run: runs the geometry branch on a frame (entering the streaming memory) and
                returns its record; raises ``ModelOutputError`` for non-finite outputs.
            boundaries: the modules at whose start the worker thread waits while a frame is
                being pushed (hooked when the worker first starts).
            lag: ``geometry_lag``: the owed outputs are taken in before the (lag + 1)-th frame
                after the owed one at the latest (``lag``: changed by a paced engine).
            cost: told the seconds each run took, time paused at a boundary left out.

        """
        self._run = run
        self._boundaries = boundaries
        self._cost = cost
        self.lag = lag
        self._gate = WorkerGate()
        self._hooks: list[torch.utils.hooks.RemovableHandle] = []
        self._worker: ThreadPoolExecutor | None = None  # created by the first ``start``
        self._owed: OwedFrame | None = None
        self.failed = False  # the last owed branch failed: geometry first until one succeeds

    @property
    def owed_index(self) -> int | None:
        """Return the index of the frame whose geometry is owed, None when none is."""
        return None if self._owed is None else self._owed.record.frame.index

    def owe(self, record: CameraSpaceFrame) -> None:
        """Owe the geometry branch of the frame whose record (without geometry) is ``record``."""
        self._owed = OwedFrame(record)

    def finished(self, record: CameraSpaceFrame, moment: Callable[[], TrackerMoment]) -> None:
        """Keep the tracker's ``moment()`` right after ``record``'s frame if that one is owed."""
        if self._owed is not None and self._owed.record is record:
            self._owed.moment = moment()

    def due(self, index: int, tracker_lost: bool, hands_sampled: Callable[[], bool]) -> bool:
        """Return whether the owed outputs are taken in before frame ``index``.

        Before the frame after the owed one, or with ``geometry_lag: n`` before the
        (n + 1)-th, or the first when that frame needs them: the tracker lost the camera and
        needs depth (``tracker_lost``; the frame runs the geometry branch first), or its hands
        are metric-scale samples while the scale warms up (``hands_sampled``, asked last: it
        waits for the frame's detection).
        """
        return self._owed is not None and (self.late(index) or tracker_lost or hands_sampled())

    def late(self, index: int) -> bool:
        """Return whether frame ``index`` comes more than ``geometry_lag`` after the owed one."""
        return index - self._owed.record.frame.index > self.lag

    @property
    def startable(self) -> bool:
        """Return whether a frame owes geometry and has been finished (its moment kept)."""
        return self._owed is not None and self._owed.moment is not None

    def start(self) -> None:
        """Start the owed geometry branch in the worker thread (once)."""
        owed = self._owed
        if owed is None or owed.run is not None:
            return
        if self._worker is None:
            self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix='geometry')
            for module in self._boundaries():
                self._hooks.append(module.register_forward_pre_hook(self._gate.boundary))
        owed.run = self._worker.submit(self._geometry, owed, True)

    def holding(self) -> contextlib.AbstractContextManager[None]:
        """Return a context inside which the worker waits at its next block boundary."""
        return self._gate.closed()

    def settle(self) -> tuple[OwedFrame, CameraSpaceFrame] | None:
        """Take the owed frame out; return it with its geometry record, None if none is owed.

        Waits for its run in the worker thread, or runs it here.

        Raises:
            ModelOutputError: for non-finite outputs (the memory is left as it was);
                ``failed`` is set until the next successful geometry branch.

        """
        owed, self._owed = self._owed, None
        if owed is None:
            return None
        try:
            record = self._geometry(owed) if owed.run is None else owed.run.result()
        except ModelOutputError:
            self.failed = True
            raise
        return owed, record

    def drain(self) -> None:
        """Forget the owed frame, waiting for its run in the worker to end (reset, close)."""
        if self._owed is not None and self._owed.run is not None:
            self._owed.run.exception()  # its worker runs on (no caller inside) and ends
        self._owed = None

    def reset(self) -> None:
        """Start a new sequence: nothing owed, no failure."""
        self.drain()
        self.failed = False

    def close(self) -> None:
        """Stop the worker thread and remove its hooks (after ``drain``)."""
        if self._worker is not None:
            self._worker.shutdown(wait=True)
        for hook in self._hooks:
            hook.remove()

    def _geometry(self, owed: OwedFrame, in_worker: bool = False) -> CameraSpaceFrame:
        """Run the geometry branch on the owed frame; return its record.

        In the caller's thread, or the worker's (``in_worker``), where the depth a new tracker
        reference or the hands' scale samples will read is computed too.
        """
        if in_worker:
            self._gate.worker = threading.get_ident()
        start, waited = time.perf_counter(), self._gate.waited_s
        record = self._run(owed.record.frame)
        if in_worker and (owed.record.hands or owed.moment.needs_depth):
            record.depth.model()
        self._cost(time.perf_counter() - start - (self._gate.waited_s - waited))
        return record
