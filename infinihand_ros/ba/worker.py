"""Bundle adjustment off the stream's thread: requests in through a queue, results out.

``plan_request`` turns a pool selection into a request (initial poses = the current corrected
poses, gauge = the oldest keyframe refined before, and the frames the pool still holds);
``run_request`` builds correspondences and solves, reusing per-keyframe features from a
``FeatureCache`` and then evicting those of frames no later selection can contain;
``BundleAdjustmentWorker`` runs requests in a background thread with its own cache, so
``submit`` never waits, and hands results to a callback and/or to ``poll``. A stream should use
``submit_selection``: the worker then plans each call when it starts, from its own correction
track holding every earlier result, so calls queued behind a running one still start from the
poses it refined and keep its gauge.
"""

from collections import deque
from collections.abc import Callable
from collections.abc import Iterable
from dataclasses import dataclass
import logging
import os
import queue
import threading
import time

import cv2
from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.corrections import CorrectionTrack
from infinihand_ros.ba.correspondences import build_problem
from infinihand_ros.ba.features import FeatureCache
from infinihand_ros.ba.keyframe import BAOutput
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.solver import BundleAdjuster
from infinihand_ros.core.errors import InputError
import numpy as np
import torch

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class BARequest:
    """One BA call's input.

    Attributes:
        keyframes: the selected keyframes, oldest first (at least two).
        T_world_cam: (K, 4, 4) initial poses (current corrected estimates).
        fixed: (K,) bool gauge.
        retained_ids: frame ids a later selection may contain (the pool's ids after this
            selection); only their cached features outlive the call.

    """

    keyframes: tuple[KeyframeInput, ...]
    T_world_cam: np.ndarray
    fixed: np.ndarray
    retained_ids: tuple[int, ...] = ()

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
                 retained_ids: Iterable[int] = ()) -> BARequest:
    """Return the request for a selection: corrected initial poses, gauge on the oldest refined.

    The fixed keyframe is the oldest one refined by an earlier call (continuity with what was
    already published); in the first call it is the oldest keyframe. ``retained_ids`` are the
    pool's frame ids after the selection (``BinaryKeyframePool.frame_ids()``), whose features
    stay cached for the next calls.
    """
    times = np.array([keyframe.timestamp_ns for keyframe in keyframes])
    raw = np.stack([keyframe.T_world_cam for keyframe in keyframes])
    refined = np.array([corrections.is_refined(t) for t in times])
    fixed = np.zeros(len(keyframes), dtype=bool)
    fixed[int(np.argmax(refined)) if refined.any() else 0] = True
    return BARequest(tuple(keyframes), corrections.correct(times, raw), fixed,
                     tuple(int(frame_id) for frame_id in retained_ids))


def run_request(request: BARequest, config: BAConfig,
                cache: FeatureCache | None = None) -> BAOutput:
    """Match the request's keyframes and solve; return the refined poses and statistics.

    With a ``cache`` (made with ``config.tracking``), features of keyframes seen in earlier
    calls are reused, and afterwards only those of ``request.retained_ids`` are kept.
    """
    start, start_cpu = time.perf_counter(), time.thread_time()
    try:
        problem = build_problem(list(request.keyframes), request.T_world_cam, request.fixed,
                                config.tracking, config.solver, cache)
    finally:
        if cache is not None:
            cache.retain(request.retained_ids)
    result = BundleAdjuster(config.solver).solve(problem)
    return BAOutput(
        frame_ids=np.array([k.frame_id for k in request.keyframes]),
        timestamps_ns=np.array([k.timestamp_ns for k in request.keyframes]),
        T_world_cam_raw=np.stack([k.T_world_cam for k in request.keyframes]),
        T_world_cam_refined=result.T_world_cam, num_tracks=len(problem.host),
        num_observations=len(problem.obs_track), num_inliers=int(result.inliers.sum()),
        seconds=time.perf_counter() - start, cpu_seconds=time.thread_time() - start_cpu)


class BundleAdjustmentWorker:
    """Background thread that runs BA requests in order, never more than a few behind.

    The thread runs with one torch thread at the configured niceness (default 19: BA takes the
    CPU time the stream leaves). When it falls behind, the oldest queued pool selection is
    dropped (counted in ``dropped``): the newest selections get refined and memory stays bounded.
    """

    def __init__(self, config: BAConfig,
                 callback: Callable[[BAOutput], None] | None = None) -> None:
        """Start the thread; each result goes to ``callback`` (if any) and to ``poll``."""
        self.config = config
        self._callback = callback
        self._queued: deque[BARequest | _Selection] = deque()
        self._wake = threading.Condition()
        self._closing = False
        self._busy = False
        self._corrections = CorrectionTrack()
        self._results: queue.Queue[BAOutput] = queue.Queue()
        self.failures = 0
        self.dropped = 0
        self._cache = FeatureCache(config.tracking)
        self._thread = threading.Thread(target=self._run, name='bundle_adjustment', daemon=True)
        self._thread.start()

    def submit(self, request: BARequest) -> None:
        """Queue a planned request and return at once."""
        self._enqueue(request)

    def submit_selection(self, keyframes: list[KeyframeInput],
                         retained_ids: Iterable[int] = ()) -> None:
        """Queue a pool selection (oldest first); it is planned when its turn comes."""
        self._enqueue(_Selection(tuple(keyframes), tuple(int(i) for i in retained_ids)))

    def _enqueue(self, item: 'BARequest | _Selection') -> None:
        """Append ``item``, dropping the oldest queued selections beyond the limit."""
        with self._wake:
            if self._closing or not self._thread.is_alive():
                raise InputError('BA worker: submit after close(); create a new worker')
            if isinstance(item, _Selection):
                limit = self.config.worker.max_queued_selections
                selections = [queued for queued in self._queued if isinstance(queued, _Selection)]
                for stale in selections[:max(0, len(selections) - limit + 1)]:
                    self._queued.remove(stale)
                    self.dropped += 1
                    logger.info('BA worker behind: dropped the selection of frames %s',
                                [k.frame_id for k in stale.keyframes])
            self._queued.append(item)
            self._wake.notify()

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

    def close(self, timeout_s: float | None = None) -> None:
        """Finish the queued requests, then stop the thread."""
        with self._wake:
            self._closing = True
            self._wake.notify()
        self._thread.join(timeout_s)

    def __enter__(self) -> 'BundleAdjustmentWorker':
        """Return the running worker."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Close the worker."""
        self.close()

    def _run(self) -> None:
        """Serve requests until closed and drained, at a low CPU priority."""
        try:  # Linux threads are tasks: only this thread yields the CPU to the stream.
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(),
                           self.config.worker.niceness)
        except (AttributeError, OSError) as exc:
            logger.info('BA worker: could not lower its priority (%s)', exc)
        torch.set_num_threads(1)  # per calling thread: the stream keeps its own thread count
        # OpenCV's pool threads would run BA's image work at normal priority: keep it in this
        # thread (process-wide; the stream's only OpenCV work is a resize per frame).
        cv2.setNumThreads(1)
        while True:
            with self._wake:
                while not self._queued and not self._closing:
                    self._wake.wait()
                if not self._queued:
                    return
                item = self._queued.popleft()
                self._busy = True
            try:
                self._serve(item)
            finally:
                with self._wake:
                    self._busy = False

    def _serve(self, request: 'BARequest | _Selection') -> None:
        """Run one request; a failed BA call is logged and counted, the thread keeps going."""
        try:
            if isinstance(request, _Selection):
                request = plan_request(list(request.keyframes), self._corrections,
                                       request.retained_ids)
            output = run_request(request, self.config, self._cache)
            self._corrections.update(output.timestamps_ns, output.T_world_cam_refined,
                                     output.T_world_cam_raw)
        except Exception:  # noqa: B902 - the thread must outlive any failed call
            self.failures += 1
            logger.exception('BA call over frames %s failed; poses stay uncorrected',
                             [k.frame_id for k in request.keyframes])
            return
        self._results.put(output)
        if self._callback is not None:
            self._callback(output)
