"""Tests of eval/detection_breakdown.py: miss causes, side and size counts, report output."""

import json

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.eval.detection_breakdown import detection_breakdown
from infinihand_ros.eval.detection_breakdown import DetectionBreakdown
from infinihand_ros.eval.matching import EvalFrame
from infinihand_ros.eval.matching import HandPrediction
from infinihand_ros.eval.matching import HandTarget
from infinihand_ros.eval.metrics import detection_metrics
from infinihand_ros.eval.metrics import match_frames
from infinihand_ros.eval.report import breakdown_table
import numpy as np
import pytest

WIDTH, HEIGHT = 640, 480
EYE = np.eye(3)
LEFT_BOX = np.array([100.0, 100.0, 140.0, 140.0])   # sqrt(area) 40 px = 0.0625 W: bin 0
RIGHT_BOX = np.array([400.0, 100.0, 480.0, 180.0])  # 80 px = 0.125 W: bin 1
BIG_BOX = np.array([200.0, 200.0, 400.0, 400.0])    # 200 px = 0.3125 W: bin 2


def _frame(intrinsics, targets, predictions):
    return EvalFrame(intrinsics, WIDTH, HEIGHT, targets, predictions)


@pytest.fixture
def frames(intrinsics, flat_hand) -> list[EvalFrame]:
    """Five frames, one per outcome (the comments name each target's expected result)."""
    joints = flat_hand()

    def target(side, box):
        return HandTarget(side, joints, EYE, box)

    def pred(side, box, score=0.9):
        return HandPrediction(side, joints, EYE, box, score)

    return [
        # left matched, right matched
        _frame(intrinsics, [target(LEFT, LEFT_BOX), target(RIGHT, RIGHT_BOX)],
               [pred(LEFT, LEFT_BOX), pred(RIGHT, RIGHT_BOX)]),
        # left: a right prediction sits on it -> side_swapped; right: the only right
        # prediction is on the left hand -> mislocated
        _frame(intrinsics, [target(LEFT, LEFT_BOX), target(RIGHT, RIGHT_BOX)],
               [pred(RIGHT, LEFT_BOX)]),
        # left: no prediction at all -> undetected
        _frame(intrinsics, [target(LEFT, LEFT_BOX)], []),
        # right (big): a right prediction below the presence threshold is not kept ->
        # undetected, and a rejected left one on it is no side swap either
        _frame(intrinsics, [target(RIGHT, BIG_BOX)],
               [pred(RIGHT, BIG_BOX, score=0.3), pred(LEFT, BIG_BOX, score=0.4)]),
        # right (big): matched
        _frame(intrinsics, [target(RIGHT, BIG_BOX)], [pred(RIGHT, BIG_BOX)]),
    ]


def test_each_missed_target_gets_its_cause_and_the_counts_add_up(frames) -> None:
    matches = match_frames(frames)
    breakdown = detection_breakdown(frames, matches)
    assert breakdown.misses == {'side_swapped': 1, 'mislocated': 1, 'undetected': 2}
    # Left: 3 targets, 1 matched; right: 4 targets, 2 matched.
    assert [(c.targets, c.matched) for c in breakdown.by_side] == [(3, 1), (4, 2)]
    # Sizes: the left box in bin 0 (3 targets, 1 matched), the right box in bin 1 (2, 1),
    # the big box in bin 2 (2, 1), nothing in bin 3.
    assert [(c.targets, c.matched) for c in breakdown.by_size] == [(3, 1), (2, 1), (2, 1), (0, 0)]
    pooled = detection_metrics(frames, matches)
    assert sum(breakdown.misses.values()) == pooled.false_negatives
    assert sum(c.matched for c in breakdown.by_side) == pooled.true_positives
    with pytest.raises(InputError, match='one FrameMatch per frame'):
        detection_breakdown(frames, matches[:-1])
    assert breakdown.by_side[LEFT].recall == pytest.approx(1 / 3)
    assert np.isnan(breakdown.by_size[3].recall)


def test_off_screen_targets_are_left_out(intrinsics, flat_hand) -> None:
    behind = flat_hand(np.array([0.0, 0.0, -0.5]))  # every joint behind the camera
    frame = _frame(intrinsics, [HandTarget(LEFT, behind, EYE, LEFT_BOX)], [])
    breakdown = detection_breakdown([frame], match_frames([frame]))
    assert [c.targets for c in breakdown.by_side] == [0, 0]
    assert sum(breakdown.misses.values()) == 0


def test_dict_and_table_report_the_same_counts(frames) -> None:
    breakdown = detection_breakdown(frames, match_frames(frames))
    data = json.loads(json.dumps(breakdown.as_dict()))  # JSON-ready, no NaN
    assert data['by_side']['left'] == {'targets': 3, 'recall': pytest.approx(1 / 3)}
    assert data['by_size'][DetectionBreakdown.size_bins()[3]] == {'targets': 0, 'recall': None}
    assert data['misses'] == {'side_swapped': 1, 'mislocated': 1, 'undetected': 2}
    table = breakdown_table(breakdown)
    assert '| left hands | 3 | 0.3333 |' in table
    assert '| size < 0.1 W | 3 | 0.3333 |' in table
    assert '| undetected | 2 | 0.5 |' in table
    assert DetectionBreakdown.size_bins() == ('< 0.1 W', '0.1-0.2 W', '0.2-0.4 W', '>= 0.4 W')
