"""Tests of eval/trajectory.py: ATE after similarity alignment, RPE over consecutive frames."""

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import make_transform
from infinihand_ros.eval.trajectory import trajectory_metrics
import numpy as np
import pytest
from scipy.spatial.transform import Rotation


def _trajectory(count: int = 12) -> np.ndarray:
    """Return a camera walking along x while turning about y."""
    angles = np.linspace(0.0, 0.6, count)
    rotations = Rotation.from_rotvec(angles[:, None] * np.array([0.0, 1.0, 0.0])).as_matrix()
    centres = np.stack([np.linspace(0.0, 1.1, count), np.zeros(count),
                        0.2 * np.sin(np.linspace(0.0, 3.0, count))], axis=1)
    return make_transform(rotations, centres)


def test_a_similar_copy_scores_zero() -> None:
    """Scaled by 0.5, rotated and shifted: ATE and RPE are 0 and the scale is recovered as 2."""
    gt = _trajectory()
    similarity = make_transform(Rotation.from_rotvec([0.3, -0.2, 1.0]).as_matrix(),
                                np.array([0.5, -1.0, 2.0]))
    pred = gt.copy()
    pred[:, :3, 3] *= 0.5
    pred = similarity @ pred
    metrics = trajectory_metrics(pred, gt)
    assert metrics.ate_m == pytest.approx(0.0, abs=1e-9)
    assert metrics.rpe_translation_m == pytest.approx(0.0, abs=1e-9)
    assert metrics.rpe_rotation_deg == pytest.approx(0.0, abs=1e-5)
    assert metrics.scale == pytest.approx(2.0)


def _umeyama_rmse(source: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    """Independent Umeyama fit (numpy SVD): RMS residual and scale of source onto target."""
    mu_s, mu_t = source.mean(axis=0), target.mean(axis=0)
    xs, xt = source - mu_s, target - mu_t
    u, d, vt = np.linalg.svd(xt.T @ xs / len(source))
    sign = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rotation = u @ sign @ vt
    scale = float(np.trace(np.diag(d) @ sign) / xs.var(axis=0).sum())
    aligned = scale * xs @ rotation.T + mu_t
    return float(np.sqrt(np.mean(np.sum((aligned - target) ** 2, axis=1)))), scale


def test_hand_computed_ate_and_rpe() -> None:
    """Identity rotations; gt centres 0, 1, 2, 3 on x; pred the same with frame 1 off on y and z.

    ATE against an independent Umeyama fit; RPE with that scale: relative steps of the
    prediction (scaled) against (1, 0, 0).
    """
    gt = make_transform(np.tile(np.eye(3), (4, 1, 1)),
                        np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0], [3.0, 0, 0]]))
    pred = gt.copy()
    pred[1, 1:3, 3] = (0.3, -0.1)
    metrics = trajectory_metrics(pred, gt)
    ate, scale = _umeyama_rmse(pred[:, :3, 3], gt[:, :3, 3])
    assert metrics.ate_m == pytest.approx(ate, rel=1e-9)
    assert metrics.scale == pytest.approx(scale, rel=1e-9)
    steps = scale * np.diff(pred[:, :3, 3], axis=0) - np.array([1.0, 0.0, 0.0])
    assert metrics.rpe_translation_m == pytest.approx(
        np.sqrt(np.mean(np.sum(steps ** 2, axis=1))), rel=1e-9)
    assert metrics.rpe_rotation_deg == 0.0


def test_a_static_prediction_scores_the_spread_of_the_truth() -> None:
    """All predicted centres equal: ATE is the RMS distance of the true centres to their mean."""
    gt = _trajectory()
    pred = np.tile(np.eye(4), (len(gt), 1, 1))
    metrics = trajectory_metrics(pred, gt)
    centres = gt[:, :3, 3]
    expected = np.sqrt(np.mean(np.sum((centres - centres.mean(axis=0)) ** 2, axis=1)))
    assert metrics.ate_m == pytest.approx(expected)


def test_bad_inputs_are_refused() -> None:
    gt = _trajectory(3)
    with pytest.raises(InputError, match='gt_T_world_cam'):
        trajectory_metrics(gt, gt[:2])
    with pytest.raises(InputError, match='more than delta'):
        trajectory_metrics(gt[:1], gt[:1])
    bad = gt.copy()
    bad[0, 0, 3] = np.nan
    with pytest.raises(InputError, match='pred_T_world_cam'):
        trajectory_metrics(bad, gt)
