"""Detection, camera-space and world-space metrics of the paper's appendix A.

Detection (FAcc, Recall, F1) and camera-space metrics (MP-p, PA-p, EPE-p, GO-p, CT-p) are computed
from ``EvalFrame`` lists after the matching in ``eval.matching``; world-space metrics (W-MPJPE,
PA-MPJPE, WA-MPJPE) from arrays of matched hand-frame pairs of one scene.

Conventions: FAcc runs over the frames that keep at least one on-screen target after the
off-screen exclusion; TP, FP and FN are pooled over all frames and both sides. Camera-space
errors are penalised means over matched and missed (on-screen) hands of all frames; EPE-p is a
mean over the on-screen target joints of those hands. Units: MP-p, PA-p and the world-space
metrics in millimetres, EPE-p in pixels, GO-p in degrees, CT-p in metres.
"""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import align_similarity
from infinihand_ros.core.geometry import project_points
from infinihand_ros.core.geometry import rotation_angle_deg
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.core.validation import as_array
from infinihand_ros.eval.matching import EvalFrame
from infinihand_ros.eval.matching import FrameMatch
from infinihand_ros.eval.matching import match_frame
import numpy as np

#: Millimetres per metre (MP-p, PA-p and the world-space metrics are reported in mm).
MM_PER_M: Final = 1000.0
#: Number of hand sides in the world-space arrays (0 left, 1 right).
NUM_SIDES: Final = len(SIDES)
#: Point sets whose mean squared spread (m^2) is below this are collapsed to a point: their best
#: similarity is the target's centroid (Umeyama's scale would divide zero by zero).
MIN_SPREAD_M2: Final = 1e-18


@dataclass(frozen=True)
class DetectionMetrics:
    """Detection metrics with the pooled counts they come from.

    Attributes:
        facc: fraction of frames with an on-screen target that have no FP and no FN.
        recall: TP / (TP + FN).
        f1: 2 TP / (2 TP + FP + FN).
        true_positives: matched hands with an on-screen target.
        false_positives: kept predictions left unmatched (all frames).
        false_negatives: on-screen targets left unmatched.
        num_frames: frames in the FAcc set (at least one on-screen target).
        num_correct_frames: frames of that set with no FP and no FN.
        num_off_screen_targets: excluded targets (and as many or fewer excluded predictions).

    """

    facc: float
    recall: float
    f1: float
    true_positives: int
    false_positives: int
    false_negatives: int
    num_frames: int
    num_correct_frames: int
    num_off_screen_targets: int

    def as_dict(self) -> dict[str, float]:
        """Return the metrics under the paper's names (FAcc, Recall, F1)."""
        return {'FAcc': self.facc, 'Recall': self.recall, 'F1': self.f1}


@dataclass(frozen=True)
class CameraSpaceMetrics:
    """Detection-penalised camera-space metrics.

    Attributes:
        mp_p_mm: root-relative joint error (MP-p), millimetres.
        pa_p_mm: per-hand Procrustes-aligned joint error (PA-p), millimetres.
        epe_p_px: 2D joint error capped at the image diagonal (EPE-p), pixels.
        go_p_deg: global orientation error (GO-p), degrees.
        ct_p_m: wrist position error (CT-p), metres.
        num_matched: matched hands (on-screen targets).
        num_missed: missed hands (on-screen targets).
        num_epe_joints: on-screen target joints averaged by EPE-p.

    """

    mp_p_mm: float
    pa_p_mm: float
    epe_p_px: float
    go_p_deg: float
    ct_p_m: float
    num_matched: int
    num_missed: int
    num_epe_joints: int

    def as_dict(self) -> dict[str, float]:
        """Return the metrics under the paper's names (MP-p, PA-p, EPE-p, GO-p, CT-p)."""
        return {'MP-p': self.mp_p_mm, 'PA-p': self.pa_p_mm, 'EPE-p': self.epe_p_px,
                'GO-p': self.go_p_deg, 'CT-p': self.ct_p_m}


@dataclass(frozen=True)
class _HandSet:
    """Stacked hands of one kind (matched or missed); ``pred_*`` are None for missed hands."""

    target_joints: np.ndarray  # (N, 21, 3) m
    target_rotation: np.ndarray  # (N, 3, 3)
    sides: np.ndarray  # (N,) int
    intrinsics: np.ndarray  # (N, 3, 3)
    diagonal_px: np.ndarray  # (N,)
    on_screen: np.ndarray  # (N, 21) bool
    pred_joints: np.ndarray | None = None  # (N, 21, 3) m
    pred_rotation: np.ndarray | None = None  # (N, 3, 3)


def root_relative_error(pred_joints: np.ndarray, target_joints: np.ndarray) -> np.ndarray:
    """Mean joint distance after subtracting each hand's wrist: (N, J, 3) x2 -> (N,)."""
    pred = np.asarray(pred_joints, dtype=np.float64)
    target = np.asarray(target_joints, dtype=np.float64)
    pred_rel = pred - pred[..., WRIST:WRIST + 1, :]
    target_rel = target - target[..., WRIST:WRIST + 1, :]
    return np.linalg.norm(pred_rel - target_rel, axis=-1).mean(axis=-1)


def _align(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Best proper similarity of ``source`` onto ``target`` (..., N, 3); no spread -> centroid."""
    aligned = align_similarity(source, target)
    spread = np.square(source - source.mean(axis=-2, keepdims=True)).sum(axis=-1).mean(axis=-1)
    collapsed = (spread < MIN_SPREAD_M2)[..., None, None]
    return np.where(collapsed, target.mean(axis=-2, keepdims=True), aligned)


def procrustes_error(pred_joints: np.ndarray, target_joints: np.ndarray) -> np.ndarray:
    """Mean joint distance after a proper similarity alignment per hand: (N, J, 3) -> (N,)."""
    target = np.asarray(target_joints, dtype=np.float64)
    aligned = _align(np.asarray(pred_joints, dtype=np.float64), target)
    return np.linalg.norm(aligned - target, axis=-1).mean(axis=-1)


def match_frames(frames: Sequence[EvalFrame]) -> list[FrameMatch]:
    """Match every frame (``eval.matching.match_frame``)."""
    for index, frame in enumerate(frames):
        if not isinstance(frame, EvalFrame):
            raise InputError(f'frames[{index}]: expected an EvalFrame, got {type(frame).__name__}')
    return [match_frame(frame) for frame in frames]


def _resolve_matches(frames: Sequence[EvalFrame],
                     matches: Sequence[FrameMatch] | None) -> list[FrameMatch]:
    if matches is None:
        matches = match_frames(frames)
    elif len(matches) != len(frames):
        raise InputError(f'matches: expected one FrameMatch per frame ({len(frames)}), '
                         f'got {len(matches)}; pass matches=None to match here')
    if not any(m.has_on_screen_target for m in matches):
        raise InputError(f'frames: none of the {len(frames)} frame(s) has an on-screen target '
                         'hand; the metrics are undefined')
    return list(matches)


def detection_metrics(frames: Sequence[EvalFrame],
                      matches: Sequence[FrameMatch] | None = None) -> DetectionMetrics:
    """FAcc, Recall and F1 over a sequence of frames (paper appendix A, detection metrics).

    Args:
        frames: evaluated frames.
        matches: the frames' ``FrameMatch`` results when already computed (else matched here).

    Raises:
        InputError: when no frame has an on-screen target, or ``matches`` does not fit.

    """
    matches = _resolve_matches(frames, matches)
    tp = sum(len(m.matched) for m in matches)
    fp = sum(len(m.false_positives) for m in matches)
    fn = sum(len(m.missed) for m in matches)
    counted = [m for m in matches if m.has_on_screen_target]
    correct = sum(m.is_correct for m in counted)
    return DetectionMetrics(
        facc=correct / len(counted), recall=tp / (tp + fn), f1=2 * tp / (2 * tp + fp + fn),
        true_positives=tp, false_positives=fp, false_negatives=fn, num_frames=len(counted),
        num_correct_frames=correct,
        num_off_screen_targets=sum(len(m.off_screen_targets) for m in matches))


def _stack_hands(frames: Sequence[EvalFrame], matches: Sequence[FrameMatch],
                 matched: bool) -> _HandSet | None:
    rows = []
    for frame, match in zip(frames, matches):
        pairs = match.matched if matched else [(t, None) for t in match.missed]
        for t, p in pairs:
            rows.append((frame.targets[t], None if p is None else frame.predictions[p], frame,
                         match.on_screen_joints[t]))
    if not rows:
        return None
    targets, preds, hand_frames, on_screen = zip(*rows)
    return _HandSet(
        target_joints=np.stack([t.joints_cam for t in targets]),
        target_rotation=np.stack([t.rotation for t in targets]),
        sides=np.array([t.side for t in targets]),
        intrinsics=np.stack([f.intrinsics for f in hand_frames]),
        diagonal_px=np.array([f.diagonal_px for f in hand_frames]),
        on_screen=np.stack(on_screen),
        pred_joints=np.stack([p.joints_cam for p in preds]) if matched else None,
        pred_rotation=np.stack([p.rotation for p in preds]) if matched else None)


def _canonical_table(canonical_joints: Mapping[int, np.ndarray] | None) -> np.ndarray:
    """Return the canonical hands as (2, 21, 3), loading the built-in skeleton when not given."""
    if canonical_joints is None:
        # Imported here so that the metrics import without the hand model when it is not needed.
        from infinihand_ros.mano.builtin import canonical_joints as builtin_canonical_joints
        canonical_joints = {side: builtin_canonical_joints(side) for side in SIDES}
    missing = [side for side in SIDES if side not in canonical_joints]
    if missing:
        raise InputError(f'canonical_joints: expected a (21, 3) array for each side {SIDES}, '
                         f'missing side(s) {missing}')
    return np.stack([as_array(canonical_joints[side], f'canonical_joints[{side}]',
                              (NUM_JOINTS, 3)) for side in SIDES])


def _matched_errors(hands: _HandSet) -> dict[str, np.ndarray]:
    """Per-hand errors of matched hands (MP, PA in m, GO deg, CT m) and EPE sum (px)."""
    pred_px = project_points(hands.pred_joints, hands.intrinsics)
    target_px = project_points(hands.target_joints, hands.intrinsics)
    capped = np.minimum(np.linalg.norm(pred_px - target_px, axis=-1), hands.diagonal_px[:, None])
    return {
        'MP': root_relative_error(hands.pred_joints, hands.target_joints),
        'PA': procrustes_error(hands.pred_joints, hands.target_joints),
        'GO': rotation_angle_deg(hands.pred_rotation, hands.target_rotation),
        'CT': np.linalg.norm(hands.pred_joints[:, WRIST] - hands.target_joints[:, WRIST], axis=-1),
        'EPE': np.where(hands.on_screen, capped, 0.0).sum(axis=-1),
    }


def _missed_penalties(hands: _HandSet, canonical: np.ndarray) -> dict[str, np.ndarray]:
    """Per-hand penalties of missed hands, as defined in the paper (same keys as matched)."""
    canonical_error = root_relative_error(canonical[hands.sides], hands.target_joints)
    return {
        'MP': canonical_error,
        'PA': canonical_error,
        'GO': rotation_angle_deg(np.eye(3), hands.target_rotation),
        'CT': np.linalg.norm(hands.target_joints[:, WRIST], axis=-1),
        'EPE': hands.diagonal_px * hands.on_screen.sum(axis=-1),
    }


def camera_space_metrics(frames: Sequence[EvalFrame],
                         canonical_joints: Mapping[int, np.ndarray] | None = None,
                         matches: Sequence[FrameMatch] | None = None) -> CameraSpaceMetrics:
    """MP-p, PA-p, EPE-p, GO-p and CT-p over a sequence of frames (paper appendix A).

    Args:
        frames: evaluated frames.
        canonical_joints: side -> (21, 3) canonical hand joints (metres) used for the missed-hand
            MP and PA penalty; by default ``infinihand_ros.mano.builtin.canonical_joints(side)``,
            imported only when a hand is missed.
        matches: the frames' ``FrameMatch`` results when already computed (else matched here).

    Raises:
        InputError: when no frame has an on-screen target, or an argument does not fit.

    """
    matches = _resolve_matches(frames, matches)
    matched = _stack_hands(frames, matches, matched=True)
    missed = _stack_hands(frames, matches, matched=False)
    parts = []
    if matched is not None:
        parts.append((_matched_errors(matched), matched.on_screen))
    if missed is not None:
        parts.append((_missed_penalties(missed, _canonical_table(canonical_joints)),
                      missed.on_screen))
    num_hands = sum(on_screen.shape[0] for _, on_screen in parts)
    num_joints = int(sum(on_screen.sum() for _, on_screen in parts))

    def total(key: str) -> float:
        return float(sum(errors[key].sum() for errors, _ in parts))

    return CameraSpaceMetrics(
        mp_p_mm=total('MP') / num_hands * MM_PER_M, pa_p_mm=total('PA') / num_hands * MM_PER_M,
        epe_p_px=total('EPE') / num_joints, go_p_deg=total('GO') / num_hands,
        ct_p_m=total('CT') / num_hands,
        num_matched=0 if matched is None else len(matched.sides),
        num_missed=0 if missed is None else len(missed.sides), num_epe_joints=num_joints)


def evaluate_frames(frames: Sequence[EvalFrame],
                    canonical_joints: Mapping[int, np.ndarray] | None = None
                    ) -> tuple[DetectionMetrics, CameraSpaceMetrics]:
    """Match the frames once and return their detection and camera-space metrics."""
    matches = match_frames(frames)
    return (detection_metrics(frames, matches),
            camera_space_metrics(frames, canonical_joints, matches))


def _check_world_inputs(pred: np.ndarray, gt: np.ndarray,
                        valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Validate the world-space inputs and return the matched pairs' joints (N, 21, 3) x2."""
    pred_array = as_array(pred, 'pred', (None, NUM_SIDES, NUM_JOINTS, 3), finite=False)
    num_frames = pred_array.shape[0]
    gt_array = as_array(gt, 'gt', (num_frames, NUM_SIDES, NUM_JOINTS, 3), finite=False)
    valid_raw = np.asarray(valid)
    if valid_raw.dtype != np.bool_:
        raise InputError(f'valid: expected a bool array of shape ({num_frames}, {NUM_SIDES}), '
                         f'got dtype {valid_raw.dtype}')
    mask = as_array(valid_raw, 'valid', (num_frames, NUM_SIDES), dtype=np.bool_, finite=False)
    if not mask.any():
        raise InputError(f'valid: no matched hand-frame pair (all {mask.size} entries False); '
                         'world-space metrics need at least one')
    for name, array in (('pred', pred_array), ('gt', gt_array)):
        bad = int(np.count_nonzero(~np.isfinite(array[mask])))
        if bad:
            raise InputError(f'{name}: {bad} value(s) are NaN or infinite in matched hand-frame '
                             'pairs (valid True); pass finite joints or mark those pairs invalid')
    return pred_array[mask], gt_array[mask]


def world_space(pred: np.ndarray, gt: np.ndarray, valid: np.ndarray) -> dict[str, float]:
    """World-space W-MPJPE, PA-MPJPE and WA-MPJPE of one scene (paper appendix A).

    Every matched hand-frame pair weighs the same (all have 21 joints). W-MPJPE compares the joints
    as given; PA-MPJPE fits a proper similarity per pair; WA-MPJPE fits one proper similarity to
    all matched joints of the scene stacked. Alignments affect only their own metric.

    Args:
        pred: (T, 2, 21, 3) predicted joints, metres, in the first camera's frame
            (frame, side [0 left, 1 right], joint, xyz); unmatched pairs may hold NaN.
        gt: (T, 2, 21, 3) target joints, same layout.
        valid: (T, 2) bool, the matched hand-frame pairs.

    Returns:
        ``{'W-MPJPE': mm, 'PA-MPJPE': mm, 'WA-MPJPE': mm}``.

    Raises:
        InputError: on a wrong shape or dtype, NaN in a matched pair, or no matched pair.

    """
    pred_joints, gt_joints = _check_world_inputs(pred, gt, valid)
    scene_aligned = _align(pred_joints.reshape(-1, 3), gt_joints.reshape(-1, 3))
    return {
        'W-MPJPE': float(np.linalg.norm(pred_joints - gt_joints, axis=-1).mean() * MM_PER_M),
        'PA-MPJPE': float(procrustes_error(pred_joints, gt_joints).mean() * MM_PER_M),
        'WA-MPJPE': float(np.linalg.norm(scene_aligned - gt_joints.reshape(-1, 3), axis=-1).mean()
                          * MM_PER_M),
    }
