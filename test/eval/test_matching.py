"""Tests of eval/matching.py: boxes, IoU, greedy matching, scores and the off-screen rule."""

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.eval.matching import box_from_projection
from infinihand_ros.eval.matching import box_iou
from infinihand_ros.eval.matching import enlarge_boxes
from infinihand_ros.eval.matching import EvalFrame
from infinihand_ros.eval.matching import greedy_match
from infinihand_ros.eval.matching import HandPrediction
from infinihand_ros.eval.matching import HandTarget
from infinihand_ros.eval.matching import match_frame
from infinihand_ros.eval.matching import on_screen_joints
import numpy as np
import pytest

WIDTH, HEIGHT = 640, 480
EYE = np.eye(3)
BOX = np.array([100.0, 100.0, 200.0, 200.0])


def _frame(intrinsics, targets=(), predictions=()):
    return EvalFrame(intrinsics, WIDTH, HEIGHT, list(targets), list(predictions))


def _target(joints, side=RIGHT, box=BOX):
    return HandTarget(side, joints, EYE, box)


def _pred(joints, side=RIGHT, box=BOX, score=None):
    return HandPrediction(side, joints, EYE, box, score)


def test_enlarge_boxes_scales_width_and_height_about_centre() -> None:
    # [0, 0, 10, 20]: centre (5, 10), size 10 x 20 -> 11 x 22 -> [-0.5, -1, 10.5, 21].
    np.testing.assert_allclose(enlarge_boxes(np.array([[0.0, 0.0, 10.0, 20.0]])),
                               [[-0.5, -1.0, 10.5, 21.0]])


def test_box_iou_known_values() -> None:
    a = np.array([[0.0, 0.0, 10.0, 10.0]])
    b = np.array([[5.0, 0.0, 15.0, 10.0],    # overlap 5 x 10 = 50, union 150 -> 1/3
                  [20.0, 20.0, 30.0, 30.0],  # disjoint -> 0
                  [0.0, 0.0, 10.0, 10.0]])   # identical -> 1
    np.testing.assert_allclose(box_iou(a, b), [[1.0 / 3.0, 0.0, 1.0]])
    # Two degenerate boxes at one point: zero union -> IoU 0, not NaN.
    assert box_iou(np.zeros((1, 4)), np.zeros((1, 4)))[0, 0] == 0.0


def test_enlarged_target_box_decides_the_threshold(intrinsics, flat_hand) -> None:
    target_box = np.array([0.0, 0.0, 200.0, 200.0])
    pred_box = np.array([175.0, 0.0, 275.0, 200.0])
    # Raw: overlap 25 x 200 = 5000, union 40000 + 20000 - 5000 = 55000 -> 0.0909 (< 0.1).
    assert box_iou(target_box, pred_box)[0, 0] == pytest.approx(5000.0 / 55000.0)
    # Enlarged target [-10, -10, 210, 210]: overlap 35 x 200 = 7000,
    # union 48400 + 20000 - 7000 = 61400 -> 0.1140 (> 0.1): matched.
    assert box_iou(enlarge_boxes(target_box), pred_box)[0, 0] == pytest.approx(7000.0 / 61400.0)
    joints = flat_hand()
    match = match_frame(_frame(intrinsics, [_target(joints, box=target_box)],
                               [_pred(joints, box=pred_box)]))
    assert match.matched == ((0, 0),)


def test_greedy_takes_pairs_in_descending_iou_not_target_order() -> None:
    # Targets in rows, predictions in columns.  A naive pass in target order would give target 0
    # its best prediction 1 (0.4) and leave target 1 without a partner (1 match).  Greedy takes
    # (1, 1) = 0.8 first, then (0, 0) = 0.3: two matches.
    iou = np.array([[0.3, 0.4], [0.0, 0.8]])
    assert greedy_match(iou, np.ones((2, 2), dtype=bool)) == [(1, 1), (0, 0)]
    # Pairs that are not allowed (other side) or at the threshold (IoU must be > 0.1) never match.
    assert greedy_match(iou, np.array([[True, True], [True, False]])) == [(0, 1)]
    assert greedy_match(np.array([[0.1]]), np.ones((1, 1), dtype=bool)) == []


def test_match_frame_is_one_to_one_and_side_aware(intrinsics, flat_hand) -> None:
    joints = flat_hand()
    near = BOX + np.array([10.0, 0.0, 10.0, 0.0])  # lower IoU than BOX itself
    frame = _frame(intrinsics, [_target(joints, RIGHT), _target(joints, LEFT, box=BOX + 300)],
                   [_pred(joints, RIGHT, box=near), _pred(joints, RIGHT, box=BOX),
                    _pred(joints, RIGHT, box=BOX + 300)])  # right pred on the left target's box
    match = match_frame(frame)
    assert match.matched == ((0, 1),)
    assert match.missed == (1,)
    assert match.false_positives == (0, 2)
    assert not match.is_correct


def test_presence_score_must_exceed_half(intrinsics, flat_hand) -> None:
    joints = flat_hand()
    cases = ((0.5, (), (0,)), (0.51, ((0, 0),), ()), (None, ((0, 0),), ()))
    for score, matched, rejected in cases:
        match = match_frame(_frame(intrinsics, [_target(joints)], [_pred(joints, score=score)]))
        assert match.matched == matched
        assert match.rejected_predictions == rejected
        assert match.false_positives == ()  # a rejected prediction is not a false positive


def test_off_screen_targets_and_their_matches_are_excluded(intrinsics, flat_hand) -> None:
    behind = flat_hand(np.array([0.0, 0.0, -0.5]))   # every joint at negative depth
    outside = flat_hand(np.array([1.0, 0.0, 0.5]))   # u = 500 * ~1 / 0.5 + 320 >> 640
    frame = _frame(intrinsics,
                   [_target(behind, box=BOX), _target(outside, box=BOX + 300)],
                   [_pred(behind, box=BOX), _pred(behind, box=BOX - 100)])
    match = match_frame(frame)
    assert match.off_screen_targets == (0, 1)
    assert match.matched == () and match.missed == ()
    assert match.excluded_predictions == (0,)
    # The unmatched prediction stays a false positive, but the frame has no on-screen target.
    assert match.false_positives == (1,)
    assert not match.has_on_screen_target


def test_on_screen_joints_borders_and_depth(intrinsics) -> None:
    # u = 500 x / z + 320: x = -0.32 at z = 0.5 -> u = 0 (inside); x = 0.32 -> u = 640 (outside).
    # A joint at depth 0.01 m is not above 0.01 m; one at 0.011 m on the axis is inside.
    joints = np.array([[-0.32, 0.0, 0.5], [0.32, 0.0, 0.5], [0.0, 0.0, 0.01], [0.0, 0.0, 0.011]])
    np.testing.assert_array_equal(on_screen_joints(joints, intrinsics, WIDTH, HEIGHT),
                                  [True, False, False, True])


def test_box_from_projection(intrinsics) -> None:
    # (0, 0, 0.5) -> (320, 240); (0.1, 0.05, 0.5) -> (320 + 100, 240 + 50).
    points = np.array([[0.0, 0.0, 0.5], [0.1, 0.05, 0.5], [0.05, 0.0, 0.5]])
    np.testing.assert_allclose(box_from_projection(points, intrinsics),
                               [320.0, 240.0, 420.0, 290.0])


@pytest.mark.parametrize('build, message', [
    (lambda j: HandTarget(RIGHT, j[:20], EYE, BOX),
     r'HandTarget.joints_cam: expected shape \(21, 3\), got \(20, 3\)'),
    (lambda j: HandTarget(2, j, EYE, BOX), r'HandTarget.side: expected a side in \(0, 1\)'),
    (lambda j: HandPrediction(RIGHT, j, EYE, BOX[[2, 1, 0, 3]]),
     r'HandPrediction.box: expected an xyxy box with x2 >= x1'),
    (lambda j: HandPrediction(RIGHT, j, EYE, BOX, float('nan')),
     r'HandPrediction.score: 1 value\(s\) are NaN'),
    (lambda j: HandPrediction(RIGHT, j, np.zeros(3), BOX),
     r'HandPrediction.rotation: expected shape \(3, 3\), got \(3,\)'),
    (lambda j: EvalFrame(np.eye(3), 0, HEIGHT),
     r'EvalFrame.width: expected a positive pixel count, got 0'),
    (lambda j: EvalFrame(np.eye(3), WIDTH, HEIGHT, [HandPrediction(RIGHT, j, EYE, BOX)]),
     r'EvalFrame.targets\[0\]: expected a HandTarget, got HandPrediction'),
])
def test_bad_inputs_raise_named_errors(flat_hand, build, message) -> None:
    with pytest.raises(InputError, match=message):
        build(flat_hand())
