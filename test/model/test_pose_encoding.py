"""Tests of model/pose_encoding.py: the 9-number layout, decoding and activation."""

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import axis_angle_to_matrix
from infinihand_ros.model.pose_encoding import activate_pose
from infinihand_ros.model.pose_encoding import camera_to_encoding
from infinihand_ros.model.pose_encoding import encoding_to_camera
from infinihand_ros.model.pose_encoding import encoding_to_matrices
import numpy as np
import pytest
import torch


def test_round_trip_through_camera_types(rng) -> None:
    """Camera -> encoding -> camera returns the same pose and intrinsics."""
    pose = CameraPose(axis_angle_to_matrix(rng.normal(size=3)), rng.normal(size=3))
    intrinsics = Intrinsics(300.0, 310.0, 112.0, 84.0, 224, 168)
    encoding = camera_to_encoding(pose, intrinsics)
    assert encoding.shape == (9,)
    np.testing.assert_allclose(encoding[:3], pose.translation)
    back_pose, back_intrinsics = encoding_to_camera(encoding, 168, 224)
    np.testing.assert_allclose(back_pose.matrix(), pose.matrix(), atol=1e-9)
    np.testing.assert_allclose([back_intrinsics.fx, back_intrinsics.fy], [300.0, 310.0])


def test_torch_decoding_matches_numpy(rng) -> None:
    """The batched torch decoder gives the numpy decoder's matrices (unnormalised quaternion)."""
    encoding = np.concatenate((rng.normal(size=3), 2.0 * rng.normal(size=4), [0.9, 1.1]))
    pose, intrinsics = encoding_to_camera(encoding, 168, 224)
    transform, k_matrix = encoding_to_matrices(torch.from_numpy(encoding)[None], 168, 224)
    np.testing.assert_allclose(transform[0].numpy(), pose.matrix(), atol=1e-9)
    np.testing.assert_allclose(k_matrix[0].numpy(), intrinsics.matrix(), atol=1e-9)


def test_activation_clamps_only_the_fovs() -> None:
    """Translation and quaternion pass through; negative FoVs become zero."""
    raw = torch.tensor([-1.0, 2.0, -3.0, -0.1, 0.2, -0.3, 0.4, -0.5, 0.6])
    expected = raw.clone()
    expected[7] = 0.0
    torch.testing.assert_close(activate_pose(raw), expected)


def test_decoding_rejects_a_bad_shape() -> None:
    """A wrong-length encoding raises InputError with the expected shape."""
    with pytest.raises(InputError, match=r'\(9,\)'):
        encoding_to_camera(np.zeros(7), 10, 10)
