"""Tests of model/pose_encoding.py: the 9-number layout, the direction, decoding and activation."""

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import axis_angle_to_matrix
from infinihand_ros.model.pose_encoding import activate_pose
from infinihand_ros.model.pose_encoding import CAM_TO_WORLD
from infinihand_ros.model.pose_encoding import cam_to_world_to_encoding
from infinihand_ros.model.pose_encoding import camera_to_encoding
from infinihand_ros.model.pose_encoding import encoding_to_cam_to_world
from infinihand_ros.model.pose_encoding import encoding_to_camera
from infinihand_ros.model.pose_encoding import encoding_to_matrices
from infinihand_ros.model.pose_encoding import POSE_DIRECTIONS
from infinihand_ros.model.pose_encoding import WORLD_TO_CAM
import numpy as np
import pytest
import torch

#: t = (1, 2, 3), a quarter turn about z (q = (0, 0, sin 45, cos 45)), fov_h 0.9, fov_w 1.1.
KNOWN = np.array([1.0, 2.0, 3.0, 0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5), 0.9, 1.1])
QUARTER_TURN_Z = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def test_known_encoding_decodes_to_camera_to_world_both_ways() -> None:
    """cam_to_world keeps [R|t]; world_to_cam gives its inverse (centre -R^T t)."""
    encoding = torch.from_numpy(KNOWN)[None]
    as_is, k_matrix = encoding_to_cam_to_world(encoding, 168, 224, CAM_TO_WORLD)
    np.testing.assert_allclose(as_is[0, :3, :3].numpy(), QUARTER_TURN_Z, atol=1e-12)
    np.testing.assert_allclose(as_is[0, :3, 3].numpy(), [1.0, 2.0, 3.0])
    inverted, k_inverted = encoding_to_cam_to_world(encoding, 168, 224, WORLD_TO_CAM)
    np.testing.assert_allclose(inverted[0, :3, :3].numpy(), QUARTER_TURN_Z.T, atol=1e-12)
    np.testing.assert_allclose(inverted[0, :3, 3].numpy(), [-2.0, 1.0, -3.0], atol=1e-12)
    np.testing.assert_allclose(inverted[0].numpy() @ as_is[0].numpy(), np.eye(4), atol=1e-12)
    torch.testing.assert_close(k_inverted, k_matrix)
    np.testing.assert_allclose(k_matrix[0].numpy(), [
        [112.0 / np.tan(0.55), 0.0, 112.0], [0.0, 84.0 / np.tan(0.45), 84.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize('direction', POSE_DIRECTIONS)
def test_torch_round_trip(direction: str, rng: np.random.Generator) -> None:
    """Poses and intrinsics -> encoding -> the same poses and intrinsics, batched."""
    rotations = axis_angle_to_matrix(rng.normal(size=(2, 3, 3)))
    poses = np.tile(np.eye(4), (2, 3, 1, 1))
    poses[..., :3, :3] = rotations
    poses[..., :3, 3] = rng.normal(size=(2, 3, 3))
    k_matrix = np.array([[300.0, 0.0, 112.0], [0.0, 310.0, 84.0], [0.0, 0.0, 1.0]])
    intrinsics = torch.from_numpy(np.tile(k_matrix, (2, 3, 1, 1)))
    encoding = cam_to_world_to_encoding(torch.from_numpy(poses), intrinsics, 168, 224,
                                        direction)
    assert encoding.shape == (2, 3, 9)
    assert bool((encoding[..., 6] >= 0).all())
    back, back_k = encoding_to_cam_to_world(encoding, 168, 224, direction)
    np.testing.assert_allclose(back.numpy(), poses, atol=1e-12)
    np.testing.assert_allclose(back_k.numpy(), intrinsics.numpy(), atol=1e-9)


@pytest.mark.parametrize('direction', POSE_DIRECTIONS)
def test_numpy_round_trip_matches_torch(direction: str, rng: np.random.Generator) -> None:
    """Camera -> encoding -> camera is exact, and the numpy encoder agrees with torch's."""
    pose = CameraPose(axis_angle_to_matrix(rng.normal(size=3)), rng.normal(size=3))
    intrinsics = Intrinsics(300.0, 310.0, 112.0, 84.0, 224, 168)
    encoding = camera_to_encoding(pose, intrinsics, direction)
    assert encoding.shape == (9,)
    back_pose, back_intrinsics = encoding_to_camera(encoding, 168, 224, direction)
    np.testing.assert_allclose(back_pose.matrix(), pose.matrix(), atol=1e-9)
    np.testing.assert_allclose([back_intrinsics.fx, back_intrinsics.fy], [300.0, 310.0])
    torch_encoding = cam_to_world_to_encoding(
        torch.from_numpy(pose.matrix()), torch.from_numpy(intrinsics.matrix()), 168, 224,
        direction)
    np.testing.assert_allclose(torch_encoding.numpy(), encoding, atol=1e-9)
    raw_translation = pose.translation if direction == CAM_TO_WORLD else \
        pose.inverse_matrix()[:3, 3]
    np.testing.assert_allclose(encoding[:3], raw_translation, atol=1e-12)


def test_raw_decoding_matches_numpy(rng: np.random.Generator) -> None:
    """The batched raw decoder gives the numpy decoder's matrices (unnormalised quaternion)."""
    encoding = np.concatenate((rng.normal(size=3), 2.0 * rng.normal(size=4), [0.9, 1.1]))
    pose, intrinsics = encoding_to_camera(encoding, 168, 224, CAM_TO_WORLD)
    transform, k_matrix = encoding_to_matrices(torch.from_numpy(encoding)[None], 168, 224)
    np.testing.assert_allclose(transform[0].numpy(), pose.matrix(), atol=1e-9)
    np.testing.assert_allclose(k_matrix[0].numpy(), intrinsics.matrix(), atol=1e-9)


def test_activation_clamps_only_the_fovs() -> None:
    """Translation and quaternion pass through; negative FoVs become zero."""
    raw = torch.tensor([-1.0, 2.0, -3.0, -0.1, 0.2, -0.3, 0.4, -0.5, 0.6])
    expected = raw.clone()
    expected[7] = 0.0
    torch.testing.assert_close(activate_pose(raw), expected)


def test_bad_shape_and_direction_are_refused() -> None:
    """A wrong-length encoding raises InputError; an unknown direction names the choices."""
    with pytest.raises(InputError, match=r'\(9,\)'):
        encoding_to_camera(np.zeros(7), 10, 10)
    with pytest.raises(ValueError, match="got 'c2w'"):
        encoding_to_cam_to_world(torch.from_numpy(KNOWN), 10, 10, 'c2w')
    with pytest.raises(ValueError, match='cam_to_world'):
        camera_to_encoding(CameraPose.identity(), Intrinsics(1, 1, 1, 1, 2, 2), 'w2c')
