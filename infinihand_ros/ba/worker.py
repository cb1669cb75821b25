"""Bundle adjustment off the stream: requests in through a queue, BA in its own process.

``plan_request`` turns a pool selection into a request (initial poses = the current corrected
poses, gauge = the oldest keyframe refined before, and the frames the pool still holds);
``run_request`` builds correspondences and solves, reusing per-keyframe features from a
``FeatureCache`` and then evicting those of frames no later selection can contain;
``BundleAdjustmentWorker`` queues requests for a background thread that runs each one in a BA
process (``ba/process.py``: its own interpreter, thread settings and priority), so ``submit``
never waits, BA shares neither the interpreter lock nor thread settings with the stream, and a
failure or crash in BA only fails that call; results go to a callback and/or to ``poll``. A
stream should use ``submit_selection``: the worker then plans each call when it starts, from
its own correction track holding the earlier results that can still matter, so calls queued
behind a running one still start from the poses it refined and keep its gauge. The worker also
remembers which frames were in a failed call and in no successful call since
(``failed_frame_ids``), so their results can say BA failed there.
"""

from collections import deque
from collections.abc import Callable
from collections.abc import Iterable
from dataclasses import dataclass
import logging
import queue
import threading
import time

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.corrections import CorrectionTrack
from infinihand_ros.ba.correspondences import build_problem
from infinihand_ros.ba.features import FeatureCache
from infinihand_ros.ba.keyframe import BAOutput
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.keyframe import rescaled
from infinihand_ros.ba.keyframe import StreamLens
from infinihand_ros.ba.process import BAProcess
from infinihand_ros.ba.process import BAProcessCrashError
from infinihand_ros.ba.process import BAProcessError
from infinihand_ros.ba.process import RunFunction
from infinihand_ros.ba.solver import BundleAdjuster
from infinihand_ros.ba.validation import check_refinement
from infinihand_ros.ba.validation import split_holdout
from infinihand_ros.ba.worker_statistics import WorkerState
from infinihand_ros.ba.worker_statistics import WorkerStatistics
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.core.errors import InputError
import numpy as np

logger = logging.getLogger(__name__)

#: A worker whose BA process died this many calls in a row, or could not be started, gives up.
MAX_CONSECUTIVE_CRASHES = 3
#: Frames of failed calls remembered by default (the newest; as many as the engine's pose track
#: holds by default).
FAILED_FRAMES_KEPT = 1024


class BAWorkerError(InfiniHandError, RuntimeError):
    """The BA worker cannot take requests: its BA process cannot run; create a new worker."""


@dataclass(frozen=True)
class BARequest:
    """One BA call's input.

    Attributes:
        keyframes: the selected keyframes, oldest first (at least two).
        T_world_cam: (K, 4, 4) initial poses (current corrected estimates).
        fixed: (K,) bool gauge.
        retained_ids: frame ids a later selection may contain (the pool's ids after this
            selection); only their cached features outlive the call.
        lens: the stream's lens from earlier calls (``build_problem``), or None.

    """

    keyframes: tuple[KeyframeInput, ...]
    T_world_cam: np.ndarray
    fixed: np.ndarray
    retained_ids: tuple[int, ...] = ()
    lens: StreamLens | None = None

    def __post_init__(self) -> None:
        count = len(self.keyframes)
        if count < 2:
            raise InputError(f'BA request: needs at least two keyframes, got {count}')
        if np.shape(self.T_world_cam) != (count, 4, 4) or np.shape(self.fixed) != (count,):
            raise InputError(f'BA request: T_world_cam {np.shape(self.T_world_cam)} and fixed '
                             f'{np.shape(self.fixed)} must match {count} keyframes')


@dataclass(frozen=True)
class _Selection:
    """A pool selection waiting to be planned by the worker."""

    keyframes: tuple[KeyframeInput, ...]
    retained_ids: tuple[int, ...]


def plan_request(keyframes: list[KeyframeInput], corrections: CorrectionTrack,
                 retained_ids: Iterable[int] = (), lens: StreamLens | None = None) -> BARequest:
    """Return the request for a selection: corrected initial poses, gauge on the oldest refined.

    The keyframes are brought to the newest one's metric scale. The fixed keyframe is the
    oldest one whose correction comes from earlier calls (refined, or between refined ones:
    continuity with what was already published); in the first call it is the oldest keyframe.
    ``corrections`` hold earlier results in model units (``PoseTrack.update_corrections``).
    ``retained_ids`` are the pool's frame ids after the selection
    (``BinaryKeyframePool.frame_ids()``), whose features stay cached for the next calls;
    ``lens`` is the stream's lens so far.
    """
    scale = keyframes[-1].scale
    keyframes = [keyframe.at_scale(scale) for keyframe in keyframes]
    times = np.array([keyframe.timestamp_ns for keyframe in keyframes])
    raw = np.stack([keyframe.T_world_cam for keyframe in keyframes])
    refined = np.array([corrections.is_covered(t) for t in times])
    fixed = np.zeros(len(keyframes), dtype=bool)
    fixed[int(np.argmax(refined)) if refined.any() else 0] = True
    start = rescaled(corrections.correct(times, rescaled(raw, 1.0 / scale)), scale)
    return BARequest(tuple(keyframes), start, fixed,
                     tuple(int(frame_id) for frame_id in retained_ids), lens)


def run_request(request: BARequest, config: BAConfig,
                cache: FeatureCache | None = None) -> BAOutput:
    """Match the request's keyframes and solve; return the refined poses and statistics.

    With a ``cache`` (made with ``config.tracking``), features of keyframes seen in earlier
    calls are reused, and afterwards only those of ``request.retained_ids`` are kept.
    """
    start, start_cpu = time.perf_counter(), time.thread_time()
    try:
        problem = build_problem(list(request.keyframes), request.T_world_cam, request.fixed,
                                config.tracking, config.solver, cache, request.lens)
    finally:
        if cache is not None:
            cache.retain(request.retained_ids)
    every = config.solver.holdout_every
    fit, held = split_holdout(problem, every) if every else (problem, None)
    result = BundleAdjuster(config.solver).solve(fit)
    check = (None if held is None
             else check_refinement(held, result.T_world_cam, result.lens, config.solver))
    accepted = check is None or check.accepted
    if not accepted:
        logger.info('BA over frames %s rejected: held-out cost %.3f -> %.3f px^2; the poses '
                    'it started from stand', [k.frame_id for k in request.keyframes],
                    check.initial_cost, check.refined_cost)
    return BAOutput(
        frame_ids=np.array([k.frame_id for k in request.keyframes]),
        timestamps_ns=np.array([k.timestamp_ns for k in request.keyframes]),
        T_world_cam_raw=np.stack([k.T_world_cam for k in request.keyframes]),
        T_world_cam_refined=(result.T_world_cam if accepted
                             else np.asarray(request.T_world_cam, dtype=np.float64)),
        num_tracks=len(fit.host), num_observations=len(fit.obs_track),
        num_inliers=int(result.inliers.sum()), seconds=time.perf_counter() - start,
        cpu_seconds=time.thread_time() - start_cpu, accepted=accepted,
        held_out_costs=((np.nan, np.nan) if check is None
                        else (check.initial_cost, check.refined_cost)),
        focal_px=float(problem.intrinsics[0, 0, 0] * np.exp(result.lens[0])),
        k1=float(result.lens[1]), scale=float(request.keyframes[-1].scale))


class BundleAdjustmentWorker:
    """Background thread that runs BA requests in order in a BA process, never far behind.

    The BA process runs with one torch thread, single-threaded OpenCV and the configured
    niceness (default 19: BA takes the CPU time the stream leaves); none of that touches the
    calling process. When the worker falls behind, the oldest queued pool selection is dropped
    (counted in ``dropped``): the newest selections get refined and memory stays bounded; with
    ``worker.when_behind: wait`` the submitter waits for room instead (offline runs). A
    failed call, a callback that raises or a BA process that dies is logged and counted, and
    the next call runs (in a new process if needed); ``statistics`` tells what happened.

    Attributes:
        run_function: what the BA process runs per request (``run_request``); a subclass may
            set another module-level function with the same signature.

    """

    run_function: RunFunction = staticmethod(run_request)

    def __init__(self, config: BAConfig,
                 callback: Callable[[BAOutput], None] | None = None,
                 failed_frames_kept: int = FAILED_FRAMES_KEPT) -> None:
        """Start the thread and the BA process; each result goes to ``callback`` and ``poll``.

        The callback runs in the worker's thread; an exception it raises is logged and counted
        in ``statistics.callback_errors``. ``failed_frame_ids`` holds at most the newest
        ``failed_frames_kept`` frame ids.
        """
        self.config = config
        self._callback = callback
        self._queued: deque[BARequest | _Selection] = deque()
        self._wake = threading.Condition()
        self._closing = False
        self._busy = False
        self._corrections = CorrectionTrack()
        self._lens: StreamLens | None = None  # the stream's lens from the accepted calls
        self._results: queue.Queue[BAOutput] = queue.Queue()
        self._counts = dict.fromkeys(('submitted', 'done', 'dropped', 'failed', 'rejected',
                                      'callback_errors'), 0)
        self._last_error: str | None = None
        self._failed_frames: set[int] = set()
        self._failed_frames_kept = failed_frames_kept
        self._fatal = False
        self._abandoning = False  # close() is killing the running call
        self._process: BAProcess | None = None
        self._thread = threading.Thread(target=self._run, name='bundle_adjustment', daemon=True)
        self._thread.start()

    @property
    def statistics(self) -> WorkerStatistics:
        """Return the state and counters (a consistent snapshot; safe from any thread)."""
        with self._wake:
            return WorkerStatistics(self._state(), **self._counts,
                                    process_starts=0 if self._process is None
                                    else self._process.starts, last_error=self._last_error)

    @property
    def state(self) -> WorkerState:
        """Return what the worker is doing now."""
        with self._wake:
            return self._state()

    @property
    def dropped(self) -> int:
        """Return the number of selections dropped so far (also in ``statistics``)."""
        return self._counts['dropped']

    @property
    def failures(self) -> int:
        """Return the number of failed calls so far (also in ``statistics``)."""
        return self._counts['failed']

    @property
    def failed_frame_ids(self) -> frozenset[int]:
        """Return the frames whose last BA call failed or was rejected by its held-out check.

        The newest ``failed_frames_kept`` of them.

        A frame refined by a later call is no longer among them.
        """
        with self._wake:
            return frozenset(self._failed_frames)

    @property
    def process_id(self) -> int | None:
        """Return the BA process's id (for diagnostics), or None when none runs."""
        process = self._process
        return None if process is None else process.pid

    def submit(self, request: BARequest) -> None:
        """Queue a planned request and return at once.

        Raises:
            InputError: after ``close()``.
            BAWorkerError: when the worker failed (``state`` is 'failed').

        """
        self._enqueue(request)

    def submit_selection(self, keyframes: list[KeyframeInput],
                         retained_ids: Iterable[int] = ()) -> None:
        """Queue a pool selection (oldest first); it is planned when its turn comes.

        Selections are expected from one ``BinaryKeyframePool``: each holds the pool's oldest
        keyframe, and no later selection reaches further back, so the worker keeps only the
        corrections from there on.

        Raises:
            InputError: after ``close()``.
            BAWorkerError: when the worker failed (``state`` is 'failed').

        """
        self._enqueue(_Selection(tuple(keyframes), tuple(int(i) for i in retained_ids)))

    def _enqueue(self, item: 'BARequest | _Selection') -> None:
        """Append ``item``; past the selection limit drop the oldest or wait (``when_behind``)."""
        with self._wake:
            self._check_accepting()
            if isinstance(item, _Selection):
                limit = self.config.worker.max_queued_selections
                if self.config.worker.when_behind == 'wait':
                    while len(self._waiting_selections()) >= limit and not self._stopped():
                        self._wake.wait()
                    self._check_accepting()
                selections = self._waiting_selections()
                for stale in selections[:max(0, len(selections) - limit + 1)]:
                    self._queued.remove(stale)
                    self._counts['dropped'] += 1
                    logger.info('BA worker behind: dropped the selection of frames %s',
                                [k.frame_id for k in stale.keyframes])
            self._queued.append(item)
            self._counts['submitted'] += 1
            self._wake.notify_all()

    def poll(self) -> list[BAOutput]:
        """Return the results finished since the last poll, oldest first (never blocks)."""
        out = []
        while True:
            try:
                out.append(self._results.get_nowait())
            except queue.Empty:
                return out

    def pending(self) -> int:
        """Return the number of requests queued or running."""
        with self._wake:
            return len(self._queued) + int(self._busy)

    def wait_idle(self, timeout_s: float | None = None) -> bool:
        """Wait until no request is queued or running (or the worker stopped).

        Returns:
            True when idle, False when ``timeout_s`` ran out first.

        """
        with self._wake:
            return self._wake.wait_for(
                lambda: not (self._queued or self._busy) or self._stopped(), timeout_s)

    def _check_accepting(self) -> None:
        """Raise unless items may be queued; the caller holds ``self._wake``."""
        if self._closing:
            raise InputError('BA worker: submit after close(); create a new worker')
        if self._fatal or not self._thread.is_alive():
            raise BAWorkerError(f'BA worker failed ({self._last_error}); nothing was '
                                'queued; create a new worker')

    def _stopped(self) -> bool:
        """Return True once the worker failed or its thread ended (caller holds the lock)."""
        return self._fatal or not self._thread.is_alive()

    def _waiting_selections(self) -> list['_Selection']:
        """Return the queued pool selections, oldest first (caller holds the lock)."""
        return [queued for queued in self._queued if isinstance(queued, _Selection)]

    def close(self, timeout_s: float | None = None) -> None:
        """Stop the thread and the BA process.

        Args:
            timeout_s: None: finish every queued call first. Otherwise the queued calls are
                dropped at once (counted in ``dropped``) and the running one gets at most
                ``timeout_s`` seconds; then it is abandoned (its process killed, counted in
                ``failed``).

        """
        with self._wake:
            self._closing = True
            if timeout_s is not None:
                self._counts['dropped'] += len(self._queued)
                self._queued.clear()
            self._wake.notify_all()
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            self._abandoning = True
            process = self._process
            if process is not None:
                process.kill()
            self._thread.join()

    def __enter__(self) -> 'BundleAdjustmentWorker':
        """Return the running worker."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Close the worker."""
        self.close()

    def _state(self) -> WorkerState:
        """Return the state; the caller holds ``self._wake``."""
        if self._fatal:
            return WorkerState.FAILED
        if self._queued or self._busy:
            return WorkerState.RUNNING
        if self._closing or not self._thread.is_alive():
            return WorkerState.STOPPED
        return WorkerState.IDLE

    def _run(self) -> None:
        """Serve requests until closed and drained; give up only when BA cannot run at all."""
        try:
            self._process = BAProcess(self.config, self.run_function)
            self._serve_queue()
        except BAProcessCrashError as exc:
            self._give_up(str(exc))
        except Exception as exc:  # noqa: B902 - recorded as the worker's state, never silent
            logger.exception('BA worker thread failed')
            self._give_up(f'{type(exc).__name__}: {exc}')
        finally:
            if self._process is not None:
                self._process.close()

    def _serve_queue(self) -> None:
        """Run queued items one by one until closed and drained."""
        crashes = 0
        while True:
            with self._wake:
                while not self._queued and not self._closing:
                    self._wake.wait()
                if not self._queued:
                    return
                item = self._queued.popleft()
                self._busy = True
                self._wake.notify_all()  # room for a producer waiting in ``_enqueue``
            try:
                crashes = 0 if self._serve(item) else crashes + 1
            finally:
                with self._wake:
                    self._busy = False
                    self._wake.notify_all()  # ``wait_idle`` callers
            if crashes >= MAX_CONSECUTIVE_CRASHES:
                raise BAProcessCrashError(f'the BA process died in {crashes} calls in a row; '
                                          f'last: {self._last_error}')

    def _give_up(self, message: str) -> None:
        """Mark the worker failed; queued items are dropped."""
        logger.error('BA worker stopped: %s', message)
        with self._wake:
            self._fatal = True
            self._last_error = message
            self._counts['dropped'] += len(self._queued)
            self._queued.clear()
            self._wake.notify_all()

    def _serve(self, request: 'BARequest | _Selection') -> bool:
        """Run one item; log and count a failure. Return False when the BA process died."""
        frame_ids = [k.frame_id for k in request.keyframes]
        try:
            if isinstance(request, _Selection):
                request = plan_request(list(request.keyframes), self._corrections,
                                       request.retained_ids, self._lens)
            output = self._process.call(request)
            self._corrections.update(output.timestamps_ns, output.T_world_cam_refined,
                                     output.T_world_cam_raw, output.scale)
            # Later selections come from the pool, which never reaches before this call's
            # oldest keyframe: older corrections cannot matter to their plans any more.
            self._corrections.prune(int(output.timestamps_ns.min()))
            if output.accepted:
                self._lens = (StreamLens(output.focal_px, output.k1, 1) if self._lens is None
                              else self._lens.updated(output.focal_px, output.k1))
        except Exception as exc:  # noqa: B902 - the thread must outlive any failed call
            self._record_failure(frame_ids, exc)
            return not isinstance(exc, BAProcessCrashError)
        with self._wake:
            self._counts['done'] += 1
            if output.accepted:
                self._failed_frames.difference_update(frame_ids)
            else:
                self._counts['rejected'] += 1
                self._remember_failed(frame_ids)
        self._results.put(output)
        if self._callback is not None:
            try:
                self._callback(output)
            except Exception as exc:  # noqa: B902 - a consumer's bug must not stop BA
                logger.exception('BA result callback failed for frames %s', frame_ids)
                with self._wake:
                    self._counts['callback_errors'] += 1
                    self._last_error = f'callback: {type(exc).__name__}: {exc}'
        return True

    def _record_failure(self, frame_ids: list[int], exc: Exception) -> None:
        """Log (with the BA process's traceback, if any), count a failed call, keep its frames.

        A call that ``close`` abandoned is only noted: nobody waits for its result.
        """
        if self._abandoning:
            logger.info('BA call over frames %s abandoned at close', frame_ids)
        else:
            remote = exc.remote_traceback if isinstance(exc, BAProcessError) else ''
            logger.error('BA call over frames %s failed; poses stay uncorrected: %s\n%s',
                         frame_ids, exc, remote, exc_info=not remote)
        with self._wake:
            self._counts['failed'] += 1
            self._last_error = f'{type(exc).__name__}: {exc}'
            self._remember_failed(frame_ids)

    def _remember_failed(self, frame_ids: list[int]) -> None:
        """Keep frames whose last call gave no refinement (the newest; caller holds the lock)."""
        self._failed_frames.update(frame_ids)
        excess = len(self._failed_frames) - self._failed_frames_kept
        if excess > 0:
            self._failed_frames.difference_update(sorted(self._failed_frames)[:excess])
