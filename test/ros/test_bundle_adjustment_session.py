"""The BA node's pool, worker and sequences without ROS (ba/session.py)."""

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import PoolConfig
from infinihand_ros.ba.keyframe import BAOutput
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.session import BundleAdjustmentSession
from infinihand_ros.ba.worker import BAWorkerError
from infinihand_ros.core.datatypes import Intrinsics
import numpy as np

SMALL = Intrinsics(4.0, 4.0, 2.0, 2.0, 4, 4)
CONFIG = BAConfig(pool=PoolConfig(trigger=3, stride=2))
S = 1_000_000_000


class FakeWorker:
    """Records selections; its callback is called by the test."""

    def __init__(self, config: BAConfig, callback) -> None:
        self.callback = callback
        self.selections: list[list[int]] = []
        self.closed_with: float | None = None
        self.failed = False

    def submit_selection(self, keyframes: list, retained_ids: list) -> None:
        if self.failed:
            raise BAWorkerError('BA worker failed (test)')
        self.selections.append([keyframe.frame_id for keyframe in keyframes])

    def close(self, timeout_s: float | None) -> None:
        self.closed_with = timeout_s


def keyframe(frame_id: int, stamp_ns: int) -> KeyframeInput:
    """Return a 4x4 keyframe at x = frame_id metres."""
    pose = np.eye(4)
    pose[0, 3] = frame_id
    return KeyframeInput(frame_id, stamp_ns, np.zeros((4, 4, 3), np.uint8),
                         np.ones((4, 4), np.float32), pose, SMALL, np.zeros((4, 4), bool))


def output(stamps: list[int], raw_x: list[float], refined_x: list[float]) -> BAOutput:
    """Return a BA result moving keyframes from raw_x to refined_x along x."""
    def poses(xs: list[float]) -> np.ndarray:
        out = np.tile(np.eye(4), (len(xs), 1, 1))
        out[:, 0, 3] = xs
        return out
    return BAOutput(np.arange(len(stamps)), np.array(stamps), poses(raw_x), poses(refined_x),
                    0, 0, 0, 0.0, 0.0)


def session() -> tuple[BundleAdjustmentSession, list, list]:
    """Return a session over fake workers, the workers made and the results handed on."""
    workers: list[FakeWorker] = []
    results: list = []

    def factory(config: BAConfig, callback) -> FakeWorker:
        workers.append(FakeWorker(config, callback))
        return workers[-1]

    return BundleAdjustmentSession(CONFIG, 2 * S, 10, results.append, factory), workers, results


def test_pool_triggers_a_selection_and_results_become_corrections() -> None:
    """N=3, K=2: the fourth keyframe selects entries 0 and 2; D = refined raw^-1."""
    runner, workers, results = session()
    started = [runner.add(keyframe(i, (i + 1) * S // 10)) for i in range(4)]
    assert started == [False, False, False, True]
    assert workers[0].selections == [[0, 2]]
    workers[0].callback(output([S // 10, 3 * S // 10], [0.0, 2.0], [0.5, 2.5]))
    (corrections,) = results
    np.testing.assert_array_equal(corrections.times_ns, [S // 10, 3 * S // 10])
    np.testing.assert_allclose(corrections.corrections[:, 0, 3], [0.5, 0.5])
    assert [stamp for stamp, _ in runner.refined_poses()] == [S // 10, 3 * S // 10]
    assert runner.refined_poses()[1][1][0, 3] == 2.5


def test_a_stamp_going_back_or_a_gap_starts_a_new_sequence() -> None:
    """An older stamp, or one over 2 s later, starts a new sequence.

    A new worker (the old one closed at once); the old worker's results are ignored and the
    refined poses forgotten.
    """
    runner, workers, results = session()
    runner.add(keyframe(0, 10 * S))
    runner.add(keyframe(1, 9 * S))
    assert len(workers) == 2 and workers[0].closed_with == 0.0 and runner.sequences == 2
    workers[0].callback(output([10 * S], [0.0], [1.0]))
    assert results == [] and runner.refined_poses() == []
    runner.add(keyframe(2, 12 * S))  # 3 s after 9 s
    assert len(workers) == 3


def test_a_failed_worker_is_replaced() -> None:
    """A worker that gave up (submit raises) is replaced by a new sequence."""
    runner, workers, _ = session()
    workers[0].failed = True
    assert not any(runner.add(keyframe(i, (i + 1) * S // 10)) for i in range(4))
    assert len(workers) == 2 and runner.sequences == 2
    runner.close(1.5)
    assert workers[1].closed_with == 1.5
