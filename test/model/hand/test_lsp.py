"""The closed-form LSP (paper eq. 5) against a brute-force solver and exact cases."""

from infinihand_ros.core import geometry
from infinihand_ros.core.errors import InputError
from infinihand_ros.model.hand.lsp import solve_lateral_translation
import numpy as np
import pytest
from scipy.optimize import least_squares
import torch


def _problem(rng: np.random.Generator, n: int = 4, j: int = 21) -> tuple[np.ndarray, ...]:
    """Random hands (N, J, 3) near the origin, noisy pixel targets, depths and intrinsics."""
    joints = rng.normal(0.0, 0.05, (n, j, 3))
    depth = rng.uniform(0.3, 0.8, n)
    k = np.tile(np.eye(3), (n, 1, 1))
    k[:, 0, 0], k[:, 1, 1] = rng.uniform(300, 900, n), rng.uniform(300, 900, n)
    k[:, 0, 2], k[:, 1, 2] = rng.uniform(100, 140, n), rng.uniform(100, 140, n)
    truth = np.concatenate([rng.normal(0, 0.1, (n, 2)), depth[:, None]], axis=1)
    targets = geometry.project_points(joints + truth[:, None], k[:, None]) + rng.normal(
        0, 3.0, (n, j, 2))
    return joints, targets, depth, k


def _brute_force(joints: np.ndarray, targets: np.ndarray, depth: float, k: np.ndarray,
                 weights: np.ndarray) -> np.ndarray:
    """Minimise the weighted pixel error of eq. 5 over (a, b) numerically."""
    def residual(ab: np.ndarray) -> np.ndarray:
        points = joints + np.array([ab[0], ab[1], depth])
        keep = points[:, 2] > geometry.MIN_PROJECTION_DEPTH_M
        err = geometry.project_points(points[keep], k) - targets[keep]
        return (np.sqrt(weights[keep])[:, None] * err).ravel()
    return least_squares(residual, np.zeros(2), xtol=1e-14, ftol=1e-14, gtol=1e-14).x


def test_matches_brute_force_with_weights(rng: np.random.Generator) -> None:
    joints, targets, depth, k = _problem(rng)
    weights = rng.uniform(0.1, 2.0, joints.shape[:2])
    got = solve_lateral_translation(*(torch.as_tensor(v) for v in (
        joints, targets, depth, k, weights))).numpy()
    for i in range(len(joints)):
        np.testing.assert_allclose(
            got[i], _brute_force(joints[i], targets[i], depth[i], k[i], weights[i]), atol=1e-8)


def test_recovers_exact_translation_without_noise(rng: np.random.Generator) -> None:
    joints, _, depth, k = _problem(rng)
    truth = rng.normal(0, 0.1, (len(joints), 2))
    points = joints + np.concatenate([truth, depth[:, None]], axis=1)[:, None]
    targets = geometry.project_points(points, k[:, None])
    got = solve_lateral_translation(*(torch.as_tensor(v) for v in (joints, targets, depth, k)))
    np.testing.assert_allclose(got.numpy(), truth, atol=1e-10)


def test_joints_behind_the_camera_are_ignored(rng: np.random.Generator) -> None:
    joints, targets, depth, k = _problem(rng, n=1)
    joints[0, :5, 2] = -depth[0] - 0.2  # five joints behind the camera
    targets[0, :5] = 1e6  # garbage that would dominate if used
    got = solve_lateral_translation(*(torch.as_tensor(v) for v in (joints, targets, depth, k)))
    expected = _brute_force(joints[0], targets[0], depth[0], k[0], np.ones(21))
    np.testing.assert_allclose(got[0].numpy(), expected, atol=1e-8)


def test_no_valid_joint_gives_zero_and_finite_gradients(rng: np.random.Generator) -> None:
    joints, targets, depth, k = (torch.as_tensor(v) for v in _problem(rng, n=2))
    depth = depth.clone()
    depth[1] = -1.0  # every joint of hand 1 behind the camera
    joints.requires_grad_(True)
    got = solve_lateral_translation(joints, targets, depth, k)
    assert torch.equal(got[1], torch.zeros(2, dtype=got.dtype))
    got.sum().backward()
    assert torch.isfinite(joints.grad).all()
    assert joints.grad[0].abs().sum() > 0


def test_gradient_matches_finite_differences(rng: np.random.Generator) -> None:
    joints, targets, depth, k = (torch.as_tensor(v) for v in _problem(rng, n=1, j=6))
    inputs = tuple(t.clone().requires_grad_(True) for t in (joints, targets, depth))
    assert torch.autograd.gradcheck(
        lambda a, b, c: solve_lateral_translation(a, b, c, k), inputs)


def test_shape_errors_name_the_input(rng: np.random.Generator) -> None:
    joints, targets, depth, k = (torch.as_tensor(v) for v in _problem(rng, n=2))
    with pytest.raises(InputError, match='LSP landmarks_px'):
        solve_lateral_translation(joints, targets[:, :5], depth, k)
    with pytest.raises(InputError, match='LSP weights'):
        solve_lateral_translation(joints, targets, depth, k, torch.ones(2, 3))
