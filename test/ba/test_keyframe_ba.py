"""Where keyframes enter BA: pool selections to the worker, and the stream's tail at its end."""

from dataclasses import dataclass
from dataclasses import field

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import PoolConfig
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.keyframe_ba import FINISH_OVERLAP
from infinihand_ros.ba.keyframe_ba import KeyframeBA
from infinihand_ros.core.datatypes import Intrinsics
import numpy as np

INTRINSICS = Intrinsics(50.0, 50.0, 16.0, 12.0, 32, 24)


@dataclass
class _Worker:
    """Stands in for ``BundleAdjustmentWorker``: keeps the selections it is given."""

    selections: list = field(default_factory=list)

    def submit_selection(self, keyframes: list, retained_ids: list) -> None:
        self.selections.append([keyframe.frame_id for keyframe in keyframes])


def _keyframe(index: int) -> KeyframeInput:
    return KeyframeInput(index, 1000 + index, np.zeros((24, 32, 3), np.uint8),
                         np.ones((24, 32), np.float32), np.eye(4), INTRINSICS,
                         np.zeros((24, 32), bool))


def test_finish_refines_the_keyframes_after_the_last_trigger_joined_to_it() -> None:
    """Pool N = 8, K = 2: a trigger at 9 keyframes; finish sends the overlap and the tail."""
    worker = _Worker()
    ba = KeyframeBA(BAConfig(pool=PoolConfig(trigger=8, stride=2)), worker)
    for index in range(12):
        ba.add(_keyframe(index))
    assert worker.selections == [[0, 2, 4, 6, 8]]
    assert ba.finish()
    assert worker.selections[-1] == [0, 2, 4, 6, 8][-FINISH_OVERLAP:] + [9, 10, 11]


def test_finish_sends_nothing_when_the_last_trigger_covered_the_newest() -> None:
    """No keyframe after the last selection: no call."""
    worker = _Worker()
    ba = KeyframeBA(BAConfig(pool=PoolConfig(trigger=8, stride=2)), worker)
    for index in range(9):
        ba.add(_keyframe(index))
    assert not ba.finish() and len(worker.selections) == 1
