"""Tests of eval/metrics.py: detection, camera-space and world-space metrics on hand-made cases."""

import sys
import types

from hypothesis import given
from hypothesis import settings
from hypothesis import strategies as st
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.eval.matching import box_from_projection
from infinihand_ros.eval.matching import EvalFrame
from infinihand_ros.eval.matching import HandPrediction
from infinihand_ros.eval.matching import HandTarget
from infinihand_ros.eval.metrics import camera_space_metrics
from infinihand_ros.eval.metrics import detection_metrics
from infinihand_ros.eval.metrics import evaluate_frames
from infinihand_ros.eval.metrics import match_frames
from infinihand_ros.eval.metrics import world_space
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

WIDTH, HEIGHT = 640, 480  # diagonal D = 800 px
EYE = np.eye(3)
BOX_L = np.array([100.0, 100.0, 200.0, 200.0])
BOX_R = np.array([400.0, 100.0, 500.0, 200.0])
OFFSET_1CM = np.array([0.01, 0.0, 0.0])
HYPOTHESIS = settings(max_examples=8, derandomize=True, deadline=None)


def _rot_z(degrees):
    return Rotation.from_euler('z', degrees, degrees=True).as_matrix()


def _frame(intrinsics, targets=(), predictions=()):
    return EvalFrame(intrinsics, WIDTH, HEIGHT, list(targets), list(predictions))


def _hand_pair(intrinsics, joints, side, pred_joints=None, pred_rotation=EYE, rotation=EYE):
    """Return a target and a prediction (or None) whose boxes come from their own joints."""
    target = HandTarget(side, joints, rotation, box_from_projection(joints, intrinsics))
    if pred_joints is None:
        return target, None
    box = box_from_projection(pred_joints, intrinsics)
    return target, HandPrediction(side, pred_joints, pred_rotation, box)


# ----------------------------------------------------------------------------- detection


def test_detection_on_a_toy_sequence(intrinsics, flat_hand) -> None:
    joints = flat_hand()
    behind = flat_hand(np.array([0.0, 0.0, -0.5]))

    def target(side, box, hand=joints):
        return HandTarget(side, hand, EYE, box)

    def pred(side, box, score=None):
        return HandPrediction(side, joints, EYE, box, score)

    frames = [
        # 0: both hands found -> TP 2, correct frame.
        _frame(intrinsics, [target(LEFT, BOX_L), target(RIGHT, BOX_R)],
               [pred(LEFT, BOX_L), pred(RIGHT, BOX_R)]),
        # 1: right found, a spurious left -> TP 1, FP 1, wrong frame.
        _frame(intrinsics, [target(RIGHT, BOX_R)], [pred(RIGHT, BOX_R), pred(LEFT, BOX_L)]),
        # 2: left missed; the right prediction's score 0.3 rejects it (no FP) -> FN 1, wrong frame.
        _frame(intrinsics, [target(LEFT, BOX_L)], [pred(RIGHT, BOX_R, score=0.3)]),
        # 3: off-screen left target and its match are excluded; the unmatched right prediction
        #    is a FP, but the frame has no on-screen target and is not in the FAcc set.
        _frame(intrinsics, [target(LEFT, BOX_L, behind)], [pred(LEFT, BOX_L), pred(RIGHT, BOX_R)]),
        # 4: nothing at all.
        _frame(intrinsics),
    ]
    result = detection_metrics(frames)
    # TP = 2 + 1 = 3, FP = 1 + 1 = 2, FN = 1; FAcc over frames 0-2 = 1/3.
    assert (result.true_positives, result.false_positives, result.false_negatives) == (3, 2, 1)
    assert result.recall == pytest.approx(3 / 4)           # 3 / (3 + 1)
    assert result.f1 == pytest.approx(6 / 9)               # 2*3 / (2*3 + 2 + 1)
    assert result.facc == pytest.approx(1 / 3)
    assert (result.num_frames, result.num_correct_frames) == (3, 1)
    assert result.num_off_screen_targets == 1
    assert result.as_dict() == {'FAcc': result.facc, 'Recall': result.recall, 'F1': result.f1}


# ----------------------------------------------------------------------------- camera space


def _canonical_from(target_joints, shift=0.02):
    """Canonical hand = the target's root-relative joints, non-wrist joints shifted 2 cm in x."""
    canonical = target_joints - target_joints[0]
    canonical[1:] += np.array([shift, 0.0, 0.0])
    return canonical


def test_camera_space_matched_and_missed_known_values(intrinsics, flat_hand) -> None:
    right = flat_hand()   # wrist (0, 0, 0.5)
    left = flat_hand()
    # Matched right hand: every joint 1 cm off in x, rotation 10 degrees off.
    matched_target, matched_pred = _hand_pair(intrinsics, right, RIGHT, right + OFFSET_1CM,
                                              pred_rotation=_rot_z(10.0))
    # Missed left hand: rotation 30 degrees from identity, wrist 0.5 m from the camera.
    missed_target, _ = _hand_pair(intrinsics, left, LEFT, rotation=_rot_z(30.0))
    frames = [_frame(intrinsics, [matched_target], [matched_pred]),
              _frame(intrinsics, [missed_target])]
    canonical = {LEFT: _canonical_from(left), RIGHT: np.zeros((21, 3))}
    detection, result = evaluate_frames(frames, canonical_joints=canonical)
    assert (detection.true_positives, detection.false_negatives) == (1, 1)
    assert (result.num_matched, result.num_missed, result.num_epe_joints) == (1, 1, 42)
    # Matched: e_MP = e_PA = 0 (pure translation), e_GO = 10 deg, e_CT = 0.01 m.
    # Missed: canonical error = 20 joints * 0.02 m / 21 = 0.4/21 m = 19.0476 mm, GO 30, CT 0.5.
    assert result.mp_p_mm == pytest.approx((0.0 + 400.0 / 21.0) / 2.0)
    assert result.pa_p_mm == pytest.approx((0.0 + 400.0 / 21.0) / 2.0, abs=1e-6)
    assert result.go_p_deg == pytest.approx((10.0 + 30.0) / 2.0)
    assert result.ct_p_m == pytest.approx((0.01 + 0.5) / 2.0)
    # EPE: 1 cm at 0.5 m depth = 500 * 0.01 / 0.5 = 10 px on 21 joints; missed hand D = 800 px
    # on 21 joints -> (21 * 10 + 21 * 800) / 42 = 405.
    assert result.epe_p_px == pytest.approx(405.0)
    assert set(result.as_dict()) == {'MP-p', 'PA-p', 'EPE-p', 'GO-p', 'CT-p'}


def test_epe_is_capped_at_the_image_diagonal(intrinsics, flat_hand) -> None:
    joints = flat_hand()
    # 1 m off in x at 0.5 m depth = 1000 px per joint, capped at D = sqrt(640^2 + 480^2) = 800.
    target = HandTarget(RIGHT, joints, EYE, BOX_R)
    pred = HandPrediction(RIGHT, joints + np.array([1.0, 0.0, 0.0]), EYE, BOX_R)
    result = camera_space_metrics([_frame(intrinsics, [target], [pred])])
    assert result.epe_p_px == pytest.approx(800.0)


def test_epe_counts_only_on_screen_target_joints(intrinsics, flat_hand) -> None:
    joints = flat_hand()
    joints[11:, 0] = 0.4  # u = 500 * 0.4 / 0.5 + 320 = 720 > 640: joints 11-20 off-screen
    pred_joints = joints + OFFSET_1CM                     # 10 px on joints 0-10
    pred_joints[11:] += 4 * OFFSET_1CM                    # 50 px on joints 11-20 (not counted)
    target, pred = _hand_pair(intrinsics, joints, RIGHT, pred_joints)
    result = camera_space_metrics([_frame(intrinsics, [target], [pred])])
    assert result.num_epe_joints == 11
    assert result.epe_p_px == pytest.approx(10.0)         # (11 * 10) / 11


def test_epe_floors_predicted_depth(intrinsics, flat_hand) -> None:
    joints = flat_hand()
    behind = joints * np.array([1.0, 1.0, -1.0])          # same x, y at z = -0.5
    target = HandTarget(RIGHT, joints, EYE, BOX_R)
    pred = HandPrediction(RIGHT, behind, EYE, BOX_R)
    result = camera_space_metrics([_frame(intrinsics, [target], [pred])])
    # Pred projects at depth 0.01: offset 500 * |(x, y)| * (1/0.01 - 1/0.5) px, capped at 800.
    expected = np.minimum(500.0 * np.linalg.norm(joints[:, :2], axis=1) * (100.0 - 2.0), 800.0)
    assert result.epe_p_px == pytest.approx(expected.mean())


def test_missed_hand_penalties_alone(intrinsics, solid_hand) -> None:
    wrist = np.array([0.0, 0.0, 0.5])
    joints = solid_hand - solid_hand[0] + wrist
    target = HandTarget(RIGHT, joints, _rot_z(90.0), BOX_R)
    canonical = {LEFT: np.zeros((21, 3)), RIGHT: _canonical_from(joints, shift=0.021)}
    result = camera_space_metrics([_frame(intrinsics, [target])], canonical_joints=canonical)
    # 20 joints * 21 mm / 21 joints = 20 mm, unaligned (PA uses the same penalty); GO 90; CT 0.5.
    assert result.mp_p_mm == pytest.approx(20.0)
    assert result.pa_p_mm == pytest.approx(20.0)
    assert result.go_p_deg == pytest.approx(90.0)
    assert result.ct_p_m == pytest.approx(0.5)
    assert result.epe_p_px == pytest.approx(800.0)


def test_camera_space_needs_no_canonical_hand_without_misses(intrinsics, flat_hand) -> None:
    # No missed hand: the default canonical hand is never loaded.
    target, pred = _hand_pair(intrinsics, flat_hand(), RIGHT, flat_hand())
    result = camera_space_metrics([_frame(intrinsics, [target], [pred])])
    assert result.mp_p_mm == 0.0 and result.ct_p_m == 0.0 and result.epe_p_px == 0.0


def test_missed_hand_uses_the_builtin_canonical_hand_by_default(intrinsics, flat_hand) -> None:
    builtin = pytest.importorskip('infinihand_ros.mano.builtin')
    if not hasattr(builtin, 'canonical_joints'):
        pytest.skip('infinihand_ros.mano.builtin.canonical_joints is not available yet')
    joints = flat_hand()
    target, _ = _hand_pair(intrinsics, joints, LEFT)
    result = camera_space_metrics([_frame(intrinsics, [target])])
    canonical = np.asarray(builtin.canonical_joints(LEFT))
    # Unaligned root-relative error of the canonical left hand against the target, in mm.
    expected = np.linalg.norm((canonical - canonical[0]) - (joints - joints[0]), axis=1).mean()
    assert result.mp_p_mm == pytest.approx(expected * 1000.0)
    assert result.mp_p_mm > 0.0


def test_default_canonical_hand_is_imported_lazily(intrinsics, flat_hand, monkeypatch) -> None:
    # A stand-in for infinihand_ros.mano.builtin: canonical hand = target shifted 2 cm (as above).
    joints = flat_hand()
    calls = []

    def canonical_joints(side: int) -> np.ndarray:
        calls.append(side)
        return _canonical_from(joints)

    monkeypatch.setitem(sys.modules, 'infinihand_ros.mano.builtin',
                        types.SimpleNamespace(canonical_joints=canonical_joints))
    target, _ = _hand_pair(intrinsics, joints, RIGHT)
    result = camera_space_metrics([_frame(intrinsics, [target])])
    assert sorted(calls) == [LEFT, RIGHT]
    assert result.mp_p_mm == pytest.approx(400.0 / 21.0)   # 20 joints * 20 mm / 21


def test_camera_space_bad_inputs(intrinsics, flat_hand) -> None:
    target, _ = _hand_pair(intrinsics, flat_hand(), LEFT)
    frames = [_frame(intrinsics, [target])]
    with pytest.raises(InputError, match=r'canonical_joints: .* missing side\(s\) \[0\]'):
        camera_space_metrics(frames, canonical_joints={RIGHT: np.zeros((21, 3))})
    with pytest.raises(InputError, match=r'canonical_joints\[1\]: expected shape \(21, 3\)'):
        camera_space_metrics(frames, {LEFT: np.zeros((21, 3)), RIGHT: np.zeros((16, 3))})
    with pytest.raises(InputError, match=r'matches: expected one FrameMatch per frame \(1\), '
                                         r'got 2'):
        detection_metrics(frames, match_frames(frames * 2))
    with pytest.raises(InputError, match=r'frames: none of the 1 frame\(s\) has an on-screen'):
        detection_metrics([_frame(intrinsics)])
    with pytest.raises(InputError, match=r'frames\[0\]: expected an EvalFrame, got str'):
        match_frames(['frame'])


# ----------------------------------------------------------------------------- world space


def _scene(hand, num_frames=3):
    """(T, 2, 21, 3) scene: the hand moved 5 cm per frame, left hand 20 cm beside the right."""
    steps = np.arange(num_frames)[:, None, None, None] * np.array([0.05, 0.0, 0.0])
    sides = np.array([[[-0.2, 0.0, 0.0]], [[0.0, 0.0, 0.0]]])
    return hand[None, None] + sides[None] + steps


def test_world_space_one_centimetre_offset(solid_hand) -> None:
    gt = _scene(solid_hand)
    valid = np.ones((3, 2), dtype=bool)
    result = world_space(gt + OFFSET_1CM, gt, valid)
    # Every joint 1 cm off -> W-MPJPE 10 mm; a translation is removed by both alignments.
    assert result['W-MPJPE'] == pytest.approx(10.0)
    assert result['PA-MPJPE'] == pytest.approx(0.0, abs=1e-6)
    assert result['WA-MPJPE'] == pytest.approx(0.0, abs=1e-6)


def test_world_space_uses_only_valid_pairs(solid_hand) -> None:
    gt = _scene(solid_hand, num_frames=2)
    pred = gt.copy()
    pred[0, 0] += OFFSET_1CM
    pred[1, 1] += 3 * OFFSET_1CM
    pred[1, 0] = np.nan                         # unmatched pair: NaN allowed
    valid = np.array([[True, False], [False, True]])
    # Pairs (0, L) 10 mm and (1, R) 30 mm -> (10 + 30) / 2 = 20 mm.
    assert world_space(pred, gt, valid)['W-MPJPE'] == pytest.approx(20.0)


def test_per_pair_alignment_differs_from_one_scene_alignment(solid_hand) -> None:
    gt = _scene(solid_hand, num_frames=2)
    pred = gt.copy()
    pred[0, 1] = 1.2 * gt[0, 1] @ _rot_z(20.0).T   # one pair with its own similarity
    result = world_space(pred, gt, np.ones((2, 2), dtype=bool))
    assert result['PA-MPJPE'] == pytest.approx(0.0, abs=1e-6)
    assert result['WA-MPJPE'] > 1.0                 # one shared transform cannot fix one pair


def test_per_hand_alignment_is_proper_rotation_only(solid_hand) -> None:
    gt = _scene(solid_hand, num_frames=1)
    mirrored = gt * np.array([-1.0, 1.0, 1.0])      # reflection: not in SO(3)
    result = world_space(mirrored, gt, np.ones((1, 2), dtype=bool))
    assert result['PA-MPJPE'] > 5.0
    assert result['WA-MPJPE'] > 5.0


def test_collapsed_prediction_aligns_to_the_target_centroid(solid_hand) -> None:
    gt = _scene(solid_hand, num_frames=1)
    pred = np.zeros_like(gt)                         # every joint at one point: no spread
    result = world_space(pred, gt, np.ones((1, 2), dtype=bool))
    # Best similarity of a point set with no spread: map it onto the target centroid.
    to_centroid = np.linalg.norm(gt - gt.mean(axis=2, keepdims=True), axis=-1).mean() * 1000.0
    assert result['PA-MPJPE'] == pytest.approx(to_centroid)
    assert np.isfinite(result['WA-MPJPE'])


@HYPOTHESIS
@given(scale=st.floats(0.5, 2.0), angles=st.tuples(*[st.floats(-3.0, 3.0)] * 3),
       shift=st.tuples(*[st.floats(-1.0, 1.0)] * 3))
def test_similarity_transformed_prediction_is_aligned(solid_hand, scale, angles, shift) -> None:
    gt = _scene(solid_hand)
    rotation = Rotation.from_rotvec(angles).as_matrix()
    shift = np.array(shift) + np.array([0.05, 0.0, 0.0])  # keep W-MPJPE clearly above 0
    pred = scale * gt @ rotation.T + shift
    result = world_space(pred, gt, np.ones((3, 2), dtype=bool))
    assert result['WA-MPJPE'] == pytest.approx(0.0, abs=1e-6)
    assert result['PA-MPJPE'] == pytest.approx(0.0, abs=1e-6)
    assert result['W-MPJPE'] > 1.0


@HYPOTHESIS
@given(seed=st.integers(0, 2**16), shift=st.floats(0.05, 0.5))
def test_alignment_never_exceeds_identity_error(solid_hand, seed, shift) -> None:
    # Offset >= 5 cm plus <= 5 mm of noise: the aligned errors stay at the noise level.
    gt = _scene(solid_hand)
    noise = np.random.default_rng(seed).uniform(-0.005, 0.005, size=gt.shape)
    pred = gt + np.array([shift, -shift, shift]) + noise
    result = world_space(pred, gt, np.ones((3, 2), dtype=bool))
    assert result['PA-MPJPE'] <= result['W-MPJPE']
    assert result['WA-MPJPE'] <= result['W-MPJPE']


@pytest.mark.parametrize('pred, gt, valid, message', [
    (np.zeros((3, 2, 21)), np.zeros((3, 2, 21, 3)), np.ones((3, 2), bool),
     r'pred: expected shape \(N, 2, 21, 3\), got \(3, 2, 21\)'),
    (np.zeros((3, 2, 21, 3)), np.zeros((4, 2, 21, 3)), np.ones((3, 2), bool),
     r'gt: expected shape \(3, 2, 21, 3\), got \(4, 2, 21, 3\)'),
    (np.zeros((3, 2, 21, 3)), np.zeros((3, 2, 21, 3)), np.ones((3, 2)),
     r'valid: expected a bool array of shape \(3, 2\), got dtype float64'),
    (np.zeros((3, 2, 21, 3)), np.zeros((3, 2, 21, 3)), np.ones(3, bool),
     r'valid: expected shape \(3, 2\), got \(3,\)'),
    (np.zeros((3, 2, 21, 3)), np.zeros((3, 2, 21, 3)), np.zeros((3, 2), bool),
     r'valid: no matched hand-frame pair \(all 6 entries False\)'),
    (np.full((3, 2, 21, 3), np.nan), np.zeros((3, 2, 21, 3)), np.eye(3, 2, dtype=bool),
     r'pred: 126 value\(s\) are NaN or infinite in matched hand-frame pairs'),
])
def test_world_space_bad_inputs(pred, gt, valid, message) -> None:
    with pytest.raises(InputError, match=message):
        world_space(pred, gt, valid)
