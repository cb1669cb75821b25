"""Torch eqs. 6 and 9 against the independent numpy reference (core/mano_frames)."""

from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.mano_frames import transform_mano_params
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.model.hand.frames import camera_to_world
from infinihand_ros.model.hand.frames import hand_to_camera
from infinihand_ros.model.hand.frames import transform_orient_transl
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
import torch

N = 5


def _params(rng: np.random.Generator) -> list[ManoParams]:
    """N random hands."""
    return [ManoParams(global_orient=rng.normal(size=3), hand_pose=rng.normal(0, 0.2, (15, 3)),
                       betas=rng.normal(size=10), transl=rng.normal(size=3)) for _ in range(N)]


def _stack(params: list[ManoParams], name: str) -> torch.Tensor:
    """Stack one field of the hands into a float64 tensor."""
    return torch.as_tensor(np.stack([getattr(p, name) for p in params]))


def _assert_same_rotation(orient: torch.Tensor, expected: np.ndarray) -> None:
    """Axis-angles can differ by 2 pi; compare the rotation matrices."""
    np.testing.assert_allclose(geometry.axis_angle_to_matrix(orient.numpy()),
                               geometry.axis_angle_to_matrix(expected), atol=1e-9)


@pytest.mark.parametrize('with_root', [False, True])
def test_hand_to_camera_matches_numpy(rng: np.random.Generator, with_root: bool) -> None:
    params = _params(rng)
    rotation_h_from_c = Rotation.random(N, random_state=3).as_matrix()
    roots = rng.normal(0, 0.05, (N, 3)) if with_root else np.zeros((N, 3))
    orient, transl = hand_to_camera(
        _stack(params, 'global_orient'), _stack(params, 'transl'),
        torch.as_tensor(rotation_h_from_c), torch.as_tensor(roots) if with_root else None)
    for i, p in enumerate(params):
        expected = transform_mano_params(p, rotation_h_from_c[i].T, np.zeros(3), roots[i])
        _assert_same_rotation(orient[i], expected.global_orient)
        np.testing.assert_allclose(transl[i].numpy(), expected.transl, atol=1e-12)


def test_camera_to_world_matches_numpy(rng: np.random.Generator) -> None:
    params = _params(rng)
    rotation = Rotation.random(N, random_state=4).as_matrix()
    position = rng.normal(size=(N, 3))
    roots = rng.normal(0, 0.05, (N, 3))
    orient, transl = camera_to_world(
        _stack(params, 'global_orient'), _stack(params, 'transl'), torch.as_tensor(rotation),
        torch.as_tensor(position), torch.as_tensor(roots))
    for i, p in enumerate(params):
        expected = transform_mano_params(p, rotation[i], position[i], roots[i])
        _assert_same_rotation(orient[i], expected.global_orient)
        np.testing.assert_allclose(transl[i].numpy(), expected.transl, atol=1e-12)


def test_hand_then_world_moves_the_joints_rigidly(rng: np.random.Generator) -> None:
    model = BuiltinHandModel(RIGHT, dtype=torch.float64)
    params = _params(rng)
    pose, betas = _stack(params, 'hand_pose'), _stack(params, 'betas')
    orient_h, transl_h = _stack(params, 'global_orient'), _stack(params, 'transl')
    rot_hc = torch.as_tensor(Rotation.random(N, random_state=5).as_matrix())
    rot_wc = torch.as_tensor(Rotation.random(N, random_state=6).as_matrix())
    position = torch.as_tensor(rng.normal(size=(N, 3)))
    orient_w, transl_w = camera_to_world(*hand_to_camera(orient_h, transl_h, rot_hc), rot_wc,
                                         position)
    joints_h = model(orient_h, pose, betas, transl_h).joints
    expected = torch.einsum('nij,nkj->nki', rot_wc @ rot_hc.transpose(1, 2), joints_h)
    expected = expected + position[:, None]
    np.testing.assert_allclose(model(orient_w, pose, betas, transl_w).joints.numpy(),
                               expected.numpy(), atol=1e-12)


def test_shape_error_names_the_input() -> None:
    with pytest.raises(InputError, match='rotation'):
        transform_orient_transl(torch.zeros(2, 3), torch.zeros(2, 3), torch.eye(3))
