"""Tests of the left/right mirror helpers on numpy arrays and torch tensors."""

from infinihand_ros.core.errors import InputError
from infinihand_ros.mano.mirror import mirror_axis_angle
from infinihand_ros.mano.mirror import mirror_points
from infinihand_ros.mano.mirror import mirror_rotation_matrix
import numpy as np
import pytest
import roma
import torch

MIRROR = np.diag([-1.0, 1.0, 1.0])


def test_points_flip_x_for_numpy_and_torch() -> None:
    points = np.array([[1.0, 2.0, 3.0], [-0.5, 0.0, 4.0]])
    np.testing.assert_array_equal(mirror_points(points), [[-1.0, 2.0, 3.0], [0.5, 0.0, 4.0]])
    tensor = torch.tensor(points, dtype=torch.float32)
    mirrored = mirror_points(tensor)
    assert isinstance(mirrored, torch.Tensor) and mirrored.dtype == torch.float32
    np.testing.assert_array_equal(mirrored.numpy(), mirror_points(points))


def test_axis_angle_mirror_matches_conjugation_by_the_mirror(rng: np.random.Generator) -> None:
    axis_angle = torch.as_tensor(rng.normal(size=(6, 3)))
    expected = torch.as_tensor(MIRROR) @ roma.rotvec_to_rotmat(axis_angle) @ torch.as_tensor(
        MIRROR)
    got = roma.rotvec_to_rotmat(mirror_axis_angle(axis_angle))
    torch.testing.assert_close(got, expected)
    torch.testing.assert_close(mirror_rotation_matrix(roma.rotvec_to_rotmat(axis_angle)),
                               expected)


def test_mirrors_are_involutions_and_keep_gradients(rng: np.random.Generator) -> None:
    values = rng.normal(size=(2, 5, 3))
    np.testing.assert_array_equal(mirror_points(mirror_points(values)), values)
    np.testing.assert_array_equal(mirror_axis_angle(mirror_axis_angle(values)), values)
    tensor = torch.tensor(values, requires_grad=True)
    mirror_points(tensor).sum().backward()
    np.testing.assert_array_equal(tensor.grad[0, 0].numpy(), [-1.0, 1.0, 1.0])


def test_wrong_trailing_shape_is_rejected() -> None:
    with pytest.raises(InputError, match=r'points: expected shape \(\.\.\., 3\), got \(4, 2\)'):
        mirror_points(np.zeros((4, 2)))
    with pytest.raises(InputError, match=r'rotation: expected shape \(\.\.\., 3, 3\)'):
        mirror_rotation_matrix(torch.zeros(3))
