"""Tests of the MANO linear-blend-skinning layer on a fake model in the official layout."""

import dataclasses
from pathlib import Path

from infinihand_ros.core.hand_conventions import MANO_TIP_VERTEX_IDS
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.core.hand_conventions import NUM_MANO_JOINTS
from infinihand_ros.core.hand_conventions import OPENPOSE_TO_MANO
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.mano.mano_file import load_mano_data
from infinihand_ros.mano.mano_file import ManoData
from infinihand_ros.mano.mano_file import NUM_VERTICES
from infinihand_ros.mano.mano_layer import ManoHandModel
import numpy as np
import pytest
import roma
from scipy.spatial.transform import Rotation
import torch

#: OpenPose indices of the 16 MANO joints and of the 5 tips.
MANO_JOINTS_IN_OPENPOSE = list(OPENPOSE_TO_MANO[:NUM_MANO_JOINTS])
TIPS_IN_OPENPOSE = list(OPENPOSE_TO_MANO[NUM_MANO_JOINTS:])


@pytest.fixture(scope='module')
def mano_data(fake_mano_dir: Path) -> ManoData:
    """Return the fake right model loaded through the chumpy-free loader."""
    return load_mano_data(fake_mano_dir / 'MANO_RIGHT.pkl')


def _inputs(rng: np.random.Generator, batch: int, pose_scale: float = 0.4,
            betas_scale: float = 1.0) -> list[torch.Tensor]:
    sizes = ((batch, 3), (batch, NUM_HAND_POSE_JOINTS, 3), (batch, NUM_BETAS), (batch, 3))
    scales = (1.0, pose_scale, betas_scale, 0.2)
    return [torch.as_tensor(rng.normal(scale=s, size=n)) for s, n in zip(scales, sizes)]


def _model(data: ManoData) -> ManoHandModel:
    return ManoHandModel(data, dtype=torch.float64)


def test_zero_pose_and_shape_reproduce_template_and_regressed_joints(mano_data: ManoData) -> None:
    model = _model(mano_data)
    out = model(*(torch.zeros_like(t) for t in _inputs(np.random.default_rng(0), 1)))
    np.testing.assert_allclose(out.vertices[0].numpy(), mano_data.v_template, atol=1e-12)
    regressed = mano_data.joint_regressor @ mano_data.v_template
    np.testing.assert_allclose(out.joints[0, MANO_JOINTS_IN_OPENPOSE].numpy(), regressed,
                               atol=1e-12)
    assert model.side == RIGHT and out.vertices.shape == (1, NUM_VERTICES, 3)


def test_translation_adds_to_joints_and_vertices(mano_data: ManoData,
                                                 rng: np.random.Generator) -> None:
    model = _model(mano_data)
    orient, pose, betas, transl = _inputs(rng, 3)
    moved = model(orient, pose, betas, transl)
    still = model(orient, pose, betas, torch.zeros_like(transl))
    torch.testing.assert_close(moved.joints - still.joints, transl[:, None].expand(3, 21, 3))
    torch.testing.assert_close(moved.vertices - still.vertices,
                               transl[:, None].expand_as(moved.vertices))


def test_global_orient_rotates_about_the_root_joint(mano_data: ManoData,
                                                    rng: np.random.Generator) -> None:
    model = _model(mano_data)
    orient, pose, betas, _ = _inputs(rng, 2)
    zero_pose, zero_transl = torch.zeros_like(pose), torch.zeros(2, 3, dtype=torch.float64)
    rest = model(torch.zeros_like(orient), zero_pose, betas, zero_transl)
    out = model(orient, zero_pose, betas, zero_transl)
    root = rest.joints[:, :1]
    rotation = roma.rotvec_to_rotmat(orient)
    for key in ('joints', 'vertices'):
        expected = torch.einsum('bij,bvj->bvi', rotation, getattr(rest, key) - root) + root
        torch.testing.assert_close(getattr(out, key), expected)
    torch.testing.assert_close(out.global_rotations, rotation[:, None].expand(2, 16, 3, 3))


def test_tips_are_the_tip_vertices(mano_data: ManoData, rng: np.random.Generator) -> None:
    out = _model(mano_data)(*_inputs(rng, 2))
    torch.testing.assert_close(out.joints[:, TIPS_IN_OPENPOSE],
                               out.vertices[:, list(MANO_TIP_VERTEX_IDS)])


def test_pose_blend_shapes_use_rotation_minus_identity_features(
        mano_data: ManoData, rng: np.random.Generator) -> None:
    # All weight on the root: skinning is the identity, leaving v_template + posedirs . feature.
    weights = np.zeros_like(mano_data.weights)
    weights[:, 0] = 1.0
    model = _model(dataclasses.replace(mano_data, weights=weights))
    _, pose, _, _ = _inputs(rng, 1)
    zeros = torch.zeros(1, 3, dtype=torch.float64)
    out = model(zeros, pose, torch.zeros(1, NUM_BETAS, dtype=torch.float64), zeros)
    feature = (Rotation.from_rotvec(pose[0].numpy()).as_matrix() - np.eye(3)).reshape(-1)
    expected = mano_data.v_template + np.einsum('vcl,l->vc', mano_data.posedirs, feature)
    np.testing.assert_allclose(out.vertices[0].numpy(), expected, atol=1e-12)


def test_rigidly_weighted_vertices_follow_their_joint(mano_data: ManoData,
                                                      rng: np.random.Generator) -> None:
    owner = np.arange(NUM_VERTICES) % NUM_MANO_JOINTS
    data = dataclasses.replace(mano_data, weights=np.eye(NUM_MANO_JOINTS)[owner],
                               posedirs=np.zeros_like(mano_data.posedirs))
    model = _model(data)
    orient, pose, betas, transl = _inputs(rng, 1)
    out = model(orient, pose, betas, transl)
    v_shaped = torch.as_tensor(data.v_template) + torch.einsum(
        'vcl,l->vc', torch.as_tensor(data.shapedirs), betas[0])
    rest_joints = model.rest_joints(betas)[0]
    joints = out.joints[0, MANO_JOINTS_IN_OPENPOSE]
    rotations = out.global_rotations[0, owner]
    expected = torch.einsum('vij,vj->vi', rotations, v_shaped - rest_joints[owner]) + joints[owner]
    torch.testing.assert_close(out.vertices[0], expected)


def test_batch_matches_single_and_gradients_reach_every_input(
        mano_data: ManoData, rng: np.random.Generator) -> None:
    model = _model(mano_data)
    inputs = [t.requires_grad_() for t in _inputs(rng, 3)]
    out = model(*inputs)
    single = model(*(t[1:2] for t in inputs))
    torch.testing.assert_close(single.vertices[0], out.vertices[1])
    torch.testing.assert_close(single.joints[0], out.joints[1])
    (out.vertices.square().sum() + out.joints.square().sum()).backward()
    for name, tensor in zip(('global_orient', 'hand_pose', 'betas', 'transl'), inputs):
        assert tensor.grad is not None and tensor.grad.abs().sum() > 0.0, name
        assert torch.all(torch.isfinite(tensor.grad)), name


def test_float32_by_default_and_side_from_the_file(fake_mano_dir: Path) -> None:
    model = ManoHandModel(load_mano_data(fake_mano_dir / 'MANO_LEFT.pkl'))
    out = model(torch.zeros(1, 3), torch.zeros(1, 15, 3), torch.zeros(1, 10), torch.zeros(1, 3))
    assert model.side == 0 and out.vertices.dtype == torch.float32
    assert model.faces.shape == (1538, 3)
