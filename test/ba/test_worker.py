"""Background BA worker: submit() returns at once, results arrive by callback and poll."""

import threading

from ba_builders import synth_keyframe
from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.corrections import CorrectionTrack
from infinihand_ros.ba.features import FeatureCache
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.worker import BundleAdjustmentWorker
from infinihand_ros.ba.worker import plan_request
from infinihand_ros.ba.worker import run_request
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest


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


def test_a_busy_worker_drops_the_oldest_queued_selections(keyframes: list) -> None:
    """Selections queued behind a busy call beyond the limit are dropped, oldest first."""
    started, release = threading.Event(), threading.Event()
    received = []

    def callback(output) -> None:
        received.append(output.frame_ids.tolist())
        started.set()
        assert release.wait(timeout=60.0)

    with BundleAdjustmentWorker(BAConfig(), callback) as worker:
        worker.submit_selection(keyframes[:3])
        assert started.wait(timeout=60.0)
        for first in (1, 2):  # queued behind the running call; the first one will be dropped
            worker.submit_selection(keyframes[first:first + 3])
        worker.submit_selection(keyframes[2:])
        assert worker.dropped == 1 and worker.pending() == 3
        release.set()
    assert received == [[0, 2, 4], [4, 6, 8], [4, 6, 8]]
    assert worker.failures == 0


def test_plan_request_fixes_the_oldest_refined_keyframe(keyframes: list) -> None:
    """First call: the oldest is fixed; later: the oldest keyframe refined before."""
    corrections = CorrectionTrack()
    first = plan_request(keyframes[:3], corrections)
    assert first.fixed.tolist() == [True, False, False]
    output = run_request(first, BAConfig())
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
    """A selection without any trackable pixel fails cleanly; the next call still runs."""
    intrinsics = Intrinsics(50.0, 50.0, 32.0, 24.0, 64, 48)
    blank = [KeyframeInput(i, i, np.zeros((48, 64, 3), np.uint8), np.ones((48, 64), np.float32),
                           np.eye(4), intrinsics, np.zeros((48, 64), bool)) for i in range(3)]
    worker = BundleAdjustmentWorker(BAConfig())
    worker.submit_selection(blank)
    worker.submit_selection(blank)
    worker.close()
    assert worker.failures == 2 and worker.poll() == []
    assert 'no feature tracks between keyframes' in caplog.text
