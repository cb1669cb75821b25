"""Background BA worker: submit() returns at once, results arrive by callback and poll."""

import os
from pathlib import Path
import threading
import time

from ba_builders import synth_keyframe
import cv2
from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import SolverConfig
from infinihand_ros.ba.config import WorkerConfig
from infinihand_ros.ba.corrections import CorrectionTrack
from infinihand_ros.ba.features import FeatureCache
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.worker import BAWorkerError
from infinihand_ros.ba.worker import BundleAdjustmentWorker
from infinihand_ros.ba.worker import plan_request
from infinihand_ros.ba.worker import run_request
from infinihand_ros.ba.worker import WorkerState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
import torch


@pytest.fixture(scope='module')
def keyframes() -> list:
    """Return 5 keyframes, 2 frames apart, of a synthetic sequence."""
    sequence = SyntheticSequence(SynthConfig(), seed=3, num_frames=10)
    return [synth_keyframe(sequence.frame(index)) for index in range(0, 10, 2)]


def test_submit_never_waits_and_results_arrive(keyframes: list) -> None:
    """While the worker is busy (its callback held), submit() still returns; both results come."""
    first_done = threading.Event()
    release = threading.Event()
    received = []

    def callback(output) -> None:
        received.append(output)
        first_done.set()
        assert release.wait(timeout=60.0)

    request = plan_request(keyframes, CorrectionTrack())
    with BundleAdjustmentWorker(BAConfig(), callback) as worker:
        worker.submit(request)
        assert first_done.wait(timeout=60.0)
        worker.submit(request)  # the worker thread is blocked: this must not wait for it
        assert len(received) == 1 and worker.pending() == 2
        release.set()
    assert len(received) == 2
    polled = worker.poll()
    assert [p.frame_ids.tolist() for p in polled] == [[0, 2, 4, 6, 8]] * 2
    assert all(p.num_inliers > 100 for p in polled)
    assert worker.failures == 0
    assert worker.poll() == []


class _HeldCallback:
    """A result callback that records frame ids and holds the worker until released."""

    def __init__(self) -> None:
        self.started, self.release = threading.Event(), threading.Event()
        self.received: list[list[int]] = []

    def __call__(self, output) -> None:
        self.received.append(output.frame_ids.tolist())
        self.started.set()
        assert self.release.wait(timeout=60.0)


def test_a_busy_worker_drops_the_oldest_queued_selections(keyframes: list) -> None:
    """Selections queued behind a busy call beyond the limit are dropped, oldest first."""
    callback = _HeldCallback()
    with BundleAdjustmentWorker(BAConfig(), callback) as worker:
        worker.submit_selection(keyframes[:3])
        assert callback.started.wait(timeout=60.0)
        for first in (1, 2):  # queued behind the running call; the first one will be dropped
            worker.submit_selection(keyframes[first:first + 3])
        worker.submit_selection(keyframes[2:])
        assert worker.dropped == 1 and worker.pending() == 3
        callback.release.set()
    assert callback.received == [[0, 2, 4], [4, 6, 8], [4, 6, 8]]
    assert worker.failures == 0


def test_a_busy_worker_in_wait_mode_holds_the_submitter_and_drops_nothing(
        keyframes: list) -> None:
    """With ``when_behind: wait`` a full queue makes submit_selection wait for room."""
    callback = _HeldCallback()
    config = BAConfig(worker=WorkerConfig(when_behind='wait'))
    with BundleAdjustmentWorker(config, callback) as worker:
        worker.submit_selection(keyframes[:3])
        assert callback.started.wait(timeout=60.0)
        for first in (1, 2):  # fill the queue (limit 2) behind the running call
            worker.submit_selection(keyframes[first:first + 3])
        third = threading.Thread(target=worker.submit_selection, args=(keyframes[2:],))
        third.start()
        third.join(timeout=1.0)
        assert third.is_alive(), 'submit_selection returned although the queue was full'
        assert worker.dropped == 0 and worker.pending() == 3
        callback.release.set()
        third.join(timeout=60.0)
        assert not third.is_alive()
        assert worker.wait_idle(timeout_s=120.0)
        assert worker.pending() == 0
    assert callback.received == [[0, 2, 4], [2, 4, 6], [4, 6, 8], [4, 6, 8]]
    assert worker.dropped == 0 and worker.failures == 0


def test_wait_idle_times_out_while_a_call_runs() -> None:
    """wait_idle(timeout_s) returns False while BA is still busy."""
    worker = _SlowWorker(BAConfig())
    try:
        worker.submit(plan_request(_blank_keyframes(), CorrectionTrack()))
        start = time.monotonic()
        assert not worker.wait_idle(timeout_s=0.5)
        assert time.monotonic() - start < 10.0
    finally:
        worker.close(timeout_s=1.0)


def test_plan_request_fixes_the_oldest_refined_keyframe(keyframes: list) -> None:
    """First call: the oldest is fixed; later: the oldest keyframe refined before."""
    corrections = CorrectionTrack()
    first = plan_request(keyframes[:3], corrections)
    assert first.fixed.tolist() == [True, False, False]
    # Exact depths: a prior as tight as BA.md's (the shipped 0.2 suits the tiny model's rough
    # depth; over 3 keyframes this close it leaves the scale loose: 6 cm off here).
    exact_depth = BAConfig(solver=SolverConfig(depth_prior_rel_sigma=0.05))
    output = run_request(first, exact_depth)
    corrections.update(output.timestamps_ns, output.T_world_cam_refined, output.T_world_cam_raw)
    second = plan_request(keyframes[1:], corrections)
    assert second.fixed.tolist() == [True, False, False, False]
    np.testing.assert_allclose(second.T_world_cam[0], output.T_world_cam_refined[1], atol=1e-9)
    # Exact keyframes and depths: the refined poses stay at the truth.
    truth = np.stack([keyframe.T_world_cam for keyframe in keyframes[:3]])
    assert np.abs(output.T_world_cam_refined[:, :3, 3] - truth[:, :3, 3]).max() < 0.01


def test_submit_after_close_is_refused(keyframes: list) -> None:
    """A closed worker says how to continue."""
    worker = BundleAdjustmentWorker(BAConfig())
    worker.close()
    with pytest.raises(InputError, match='create a new worker'):
        worker.submit(plan_request(keyframes, CorrectionTrack()))


def test_run_request_keeps_only_retained_features(keyframes: list) -> None:
    """After a call the cache holds the frames the pool still has; they are not recomputed."""
    config = BAConfig()
    cache = FeatureCache(config.tracking)
    corrections = CorrectionTrack()
    run_request(plan_request(keyframes[:3], corrections, retained_ids=[2, 4, 99]), config, cache)
    assert len(cache) == 2 and cache.computed == 3
    run_request(plan_request(keyframes[1:4], corrections), config, cache)
    assert len(cache) == 0 and cache.computed == 4


def test_failed_calls_are_counted_and_the_worker_lives_on(
        caplog: pytest.LogCaptureFixture) -> None:
    """A selection without any trackable pixel fails cleanly; the next call still runs.

    The failed calls' frames are remembered, the newest ``failed_frames_kept`` of them.
    """
    worker = BundleAdjustmentWorker(BAConfig(), failed_frames_kept=2)
    worker.submit_selection(_blank_keyframes())
    worker.submit_selection(_blank_keyframes())
    worker.close()
    assert worker.failures == 2 and worker.poll() == []
    assert worker.failed_frame_ids == {1, 2}
    assert 'no feature tracks between keyframes' in caplog.text


def _blank_keyframes() -> list[KeyframeInput]:
    """Return 3 black keyframes: no trackable pixel, so a BA call over them fails."""
    intrinsics = Intrinsics(50.0, 50.0, 32.0, 24.0, 64, 48)
    return [KeyframeInput(i, i, np.zeros((48, 64, 3), np.uint8), np.ones((48, 64), np.float32),
                          np.eye(4), intrinsics, np.zeros((48, 64), bool)) for i in range(3)]


def _crash(request: object, config: BAConfig, cache: FeatureCache) -> None:
    """Kill the BA process it runs in (a stand-in for a crash in native code)."""
    os._exit(5)


def _sleep(request: object, config: BAConfig, cache: FeatureCache) -> None:
    """Take far longer than any test waits."""
    time.sleep(120.0)


class _CrashingWorker(BundleAdjustmentWorker):
    run_function = staticmethod(_crash)


class _SlowWorker(BundleAdjustmentWorker):
    run_function = staticmethod(_sleep)


def _torch_threads_in_a_new_thread() -> int:
    """Return torch's thread count as a thread started now sees it."""
    seen = []
    thread = threading.Thread(target=lambda: seen.append(torch.get_num_threads()))
    thread.start()
    thread.join()
    return seen[0]


def _nice_values(pid: int) -> set[int]:
    """Return the niceness values of the threads of process ``pid`` (Linux /proc).

    A thread that ends while they are read (one just joined) is left out.
    """
    values = set()
    for task in Path(f'/proc/{pid}/task').iterdir():
        try:
            stat = (task / 'stat').read_text()
        except FileNotFoundError:
            continue
        values.add(int(stat.rsplit(')', 1)[1].split()[16]))
    return values


@pytest.mark.skipif(not Path('/proc/self/task').exists(), reason='needs Linux /proc')
def test_ba_leaves_the_callers_thread_settings_alone(keyframes: list) -> None:
    """After a BA call, torch and OpenCV thread counts and niceness here are what they were.

    Only the BA process runs niced (all its threads); the worker's own thread is not niced.
    """
    before = (torch.get_num_threads(), _torch_threads_in_a_new_thread(), cv2.getNumThreads(),
              _nice_values(os.getpid()))
    with BundleAdjustmentWorker(BAConfig(worker=WorkerConfig(niceness=11))) as worker:
        worker.submit(plan_request(keyframes[:3], CorrectionTrack()))
        while worker.pending():
            time.sleep(0.01)
        assert _nice_values(worker.process_id) == {11}
    assert worker.poll() and worker.statistics.done == 1
    after = (torch.get_num_threads(), _torch_threads_in_a_new_thread(), cv2.getNumThreads(),
             _nice_values(os.getpid()))
    assert after == before


def test_state_and_statistics_follow_the_calls(keyframes: list) -> None:
    """State goes idle, running (callback included), idle, stopped; counters add up."""
    started, release = threading.Event(), threading.Event()

    def callback(output) -> None:
        started.set()
        assert release.wait(timeout=60.0)

    worker = BundleAdjustmentWorker(BAConfig(), callback)
    assert worker.state == WorkerState.IDLE == 'idle'
    worker.submit_selection(keyframes[:3])
    assert started.wait(timeout=60.0)
    assert worker.state == 'running' and worker.statistics.submitted == 1
    release.set()
    while worker.pending():
        time.sleep(0.01)
    assert worker.state == 'idle'
    worker.close()
    stats = worker.statistics
    assert stats.state == 'stopped' and worker.state == WorkerState.STOPPED
    assert (stats.submitted, stats.done, stats.dropped, stats.failed) == (1, 1, 0, 0)
    assert stats.callback_errors == 0 and stats.process_starts == 1 and stats.last_error is None


def test_callback_errors_are_counted_and_the_worker_lives_on(
        keyframes: list, caplog: pytest.LogCaptureFixture) -> None:
    """A callback that raises is logged and counted; results still arrive, later calls run."""
    def callback(output) -> None:
        raise KeyError('consumer bug')

    request = plan_request(keyframes[:3], CorrectionTrack())
    with BundleAdjustmentWorker(BAConfig(), callback) as worker:
        worker.submit(request)
        worker.submit(request)
    stats = worker.statistics
    assert stats.done == 2 and stats.callback_errors == 2 and stats.failed == 0
    assert len(worker.poll()) == 2 and "KeyError: 'consumer bug'" in stats.last_error
    assert 'BA result callback failed' in caplog.text


def test_after_a_failed_call_the_next_submit_works(keyframes: list) -> None:
    """A failing selection is counted with its error; the next selection is accepted and runs.

    The failed call's frames stay in ``failed_frame_ids`` until a later call refines them
    (the held-out check is off: these keyframes' true poses leave BA nothing to improve).
    """
    with BundleAdjustmentWorker(BAConfig(solver=SolverConfig(holdout_every=0))) as worker:
        worker.submit_selection(_blank_keyframes())
        while worker.pending():
            time.sleep(0.01)
        assert worker.statistics.failed == 1 and worker.state == 'idle'
        assert 'no feature tracks between keyframes' in worker.statistics.last_error
        assert worker.failed_frame_ids == {0, 1, 2}
        worker.submit_selection(keyframes[:3])  # no 'submit after close()' here
    stats = worker.statistics
    assert (stats.submitted, stats.done, stats.failed) == (2, 1, 1)
    assert [output.frame_ids.tolist() for output in worker.poll()] == [[0, 2, 4]]
    assert worker.failed_frame_ids == {1}


def test_a_ba_process_that_keeps_dying_fails_the_worker_clearly(keyframes: list) -> None:
    """Each death fails one call and starts a new process; after 3 in a row the worker fails."""
    worker = _CrashingWorker(BAConfig())
    request = plan_request(keyframes[:3], CorrectionTrack())
    for _ in range(3):
        worker.submit(request)
    deadline = time.monotonic() + 120.0
    while worker.state != 'failed' and time.monotonic() < deadline:
        time.sleep(0.05)
    stats = worker.statistics
    assert stats.state == 'failed' and stats.failed == 3 and stats.process_starts == 3
    assert 'died in 3 calls in a row' in stats.last_error and 'exit code 5' in stats.last_error
    with pytest.raises(BAWorkerError, match='create a new worker'):
        worker.submit(request)
    worker.close()
    assert worker.state == 'failed'


def test_close_with_a_timeout_abandons_a_stuck_call(keyframes: list) -> None:
    """close(timeout_s) returns soon: the running call fails, the queued one is dropped."""
    worker = _SlowWorker(BAConfig())
    request = plan_request(keyframes[:3], CorrectionTrack())
    worker.submit(request)
    worker.submit(request)
    while worker.process_id is None:
        time.sleep(0.01)
    time.sleep(0.2)  # the first call is on its way to the (sleeping) BA process
    start = time.monotonic()
    worker.close(timeout_s=0.5)
    assert time.monotonic() - start < 30.0
    stats = worker.statistics
    assert (stats.state, stats.submitted, stats.done, stats.failed, stats.dropped) == \
        ('stopped', 2, 0, 1, 1)
