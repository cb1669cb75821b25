"""Property tests of the built-in hand skeleton."""


from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import FINGER_JOINTS
from infinihand_ros.core.hand_conventions import JOINT_PARENTS
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.mano.mirror import mirror_axis_angle
from infinihand_ros.mano.mirror import mirror_points
from infinihand_ros.mano.mirror import mirror_rotation_matrix
import numpy as np
import pytest
import roma
import torch

THUMB, INDEX, MIDDLE, RING, PINKY = FINGER_JOINTS
BONES = [(JOINT_PARENTS[j], j) for j in range(1, NUM_JOINTS)]
#: Realistic adult sizes (m): wrist to middle fingertip, MCP centres index to pinky.
HAND_LENGTH_RANGE_M = (0.17, 0.20)
MCP_SPAN_RANGE_M = (0.05, 0.065)
#: Forward passes timed for the speed check; the best one must stay under this (s).


def _zeros(batch: int = 1) -> tuple[torch.Tensor, ...]:
    return (torch.zeros(batch, 3), torch.zeros(batch, NUM_HAND_POSE_JOINTS, 3),
            torch.zeros(batch, NUM_BETAS), torch.zeros(batch, 3))


def _random_inputs(rng: np.random.Generator, batch: int) -> tuple[torch.Tensor, ...]:
    def tensor(scale: float, *shape: int) -> torch.Tensor:
        return torch.as_tensor(rng.normal(scale=scale, size=shape), dtype=torch.float32)

    return (tensor(1.0, batch, 3), tensor(0.5, batch, NUM_HAND_POSE_JOINTS, 3),
            tensor(1.0, batch, NUM_BETAS), tensor(0.3, batch, 3))


def _bone_lengths(joints: torch.Tensor) -> torch.Tensor:
    return torch.stack([(joints[:, c] - joints[:, p]).norm(dim=-1) for p, c in BONES], dim=-1)


def test_zero_pose_is_a_flat_hand_of_adult_size() -> None:
    joints = BuiltinHandModel(RIGHT)(*_zeros()).joints[0].numpy()
    np.testing.assert_array_equal(joints[0], 0.0)
    others = [j for j in range(1, NUM_JOINTS) if j not in THUMB]
    np.testing.assert_array_equal(joints[others, 1], 0.0)  # wrist and fingers in the plane y=0
    assert np.all(joints[list(THUMB), 1] < 0.0)  # the rest thumb sits in front of the palm
    assert HAND_LENGTH_RANGE_M[0] < np.linalg.norm(joints[MIDDLE[-1]]) < HAND_LENGTH_RANGE_M[1]
    span = np.linalg.norm(joints[INDEX[0]] - joints[PINKY[0]])
    assert MCP_SPAN_RANGE_M[0] < span < MCP_SPAN_RANGE_M[1]
    for finger in (INDEX, MIDDLE, RING, PINKY):
        assert np.all(np.diff(joints[list(finger), 0]) < 0.0)  # pointing along -x
    assert np.all(np.diff(joints[list(THUMB), 2]) > 0.0)  # the thumb points towards +z
    assert joints[INDEX[0], 2] > joints[MIDDLE[0], 2] > joints[RING[0], 2] > joints[PINKY[0], 2]


def test_bone_lengths_do_not_depend_on_pose(rng: np.random.Generator) -> None:
    model = BuiltinHandModel(RIGHT)
    orient, pose, betas, transl = _random_inputs(rng, 8)
    posed = model(orient, pose, betas, transl).joints
    rest = model(torch.zeros_like(orient), torch.zeros_like(pose), betas,
                 torch.zeros_like(transl)).joints
    torch.testing.assert_close(_bone_lengths(posed), _bone_lengths(rest), atol=1e-6, rtol=0)


def test_wrist_is_transl_and_orient_rotates_about_it(rng: np.random.Generator) -> None:
    model = BuiltinHandModel(RIGHT, dtype=torch.float64)
    orient, _, betas, transl = (t.double() for t in _random_inputs(rng, 3))
    zero_pose = torch.zeros(3, NUM_HAND_POSE_JOINTS, 3, dtype=torch.float64)
    out = model(orient, zero_pose, betas, transl)
    rest = model(torch.zeros_like(orient), zero_pose, betas, torch.zeros_like(transl))
    torch.testing.assert_close(out.joints[:, 0], transl)
    rotation = roma.rotvec_to_rotmat(orient)
    expected = torch.einsum('bij,bkj->bki', rotation, rest.joints) + transl[:, None]
    torch.testing.assert_close(out.joints, expected)
    torch.testing.assert_close(out.global_rotations[:, 0], rotation)


def test_positive_rotation_about_z_flexes_fingers_towards_the_palm() -> None:
    orient, pose, betas, transl = _zeros()
    pose[0, 0] = torch.tensor([0.0, 0.0, 1.0])  # index1 (MCP) by 1 rad about +z
    joints = BuiltinHandModel(RIGHT)(orient, pose, betas, transl).joints[0]
    assert joints[INDEX[-1], 1] < -0.03  # the index tip moves to the palm side (-y)
    assert joints[MIDDLE[-1], 1] == 0.0


def test_size_beta_scales_every_bone_monotonically_and_each_beta_acts() -> None:
    model = BuiltinHandModel(RIGHT)
    orient, pose, _, transl = _zeros(7)
    betas = torch.zeros(7, NUM_BETAS)
    betas[:, 0] = torch.linspace(-3.0, 3.0, 7)
    lengths = _bone_lengths(model(orient, pose, betas, transl).joints)
    assert torch.all(lengths.diff(dim=0) > 0.0)
    ratio = lengths[4] / lengths[3]  # +1 SD of size: about +5 % on every bone
    torch.testing.assert_close(ratio, torch.full_like(ratio, float(np.exp(0.05))))
    rest = _bone_lengths(model(*_zeros()).joints)[0]
    unit = torch.eye(NUM_BETAS)
    for beta in range(NUM_BETAS):
        changed = _bone_lengths(model(orient[:1], pose[:1], unit[beta:beta + 1],
                                      transl[:1]).joints)[0]
        relative = (changed / rest - 1.0).abs().max()
        assert 0.01 < relative < 0.06, f'beta {beta} changes bones by {relative:.3f}'


def test_gradients_reach_every_input(rng: np.random.Generator) -> None:
    inputs = [t.requires_grad_() for t in _random_inputs(rng, 2)]
    out = BuiltinHandModel(LEFT)(*inputs)
    (out.joints.square().sum() + out.global_rotations.sum()).backward()
    for name, tensor in zip(('global_orient', 'hand_pose', 'betas', 'transl'), inputs):
        assert tensor.grad is not None and torch.all(torch.isfinite(tensor.grad)), name
        assert tensor.grad.abs().sum() > 0.0, name


def test_left_hand_is_the_mirrored_right_hand(rng: np.random.Generator) -> None:
    orient, pose, betas, transl = _random_inputs(rng, 5)
    left = BuiltinHandModel(LEFT)(orient, pose, betas, transl)
    right = BuiltinHandModel(RIGHT)(mirror_axis_angle(orient), mirror_axis_angle(pose), betas,
                                    mirror_points(transl))
    torch.testing.assert_close(left.joints, mirror_points(right.joints), atol=1e-6, rtol=0)
    torch.testing.assert_close(left.global_rotations,
                               mirror_rotation_matrix(right.global_rotations), atol=1e-6, rtol=0)


def test_batch_equals_single_hands(rng: np.random.Generator) -> None:
    model = BuiltinHandModel(RIGHT)
    inputs = _random_inputs(rng, 4)
    batch = model(*inputs)
    for index in range(4):
        single = model(*(t[index:index + 1] for t in inputs))
        torch.testing.assert_close(single.joints[0], batch.joints[index])
        torch.testing.assert_close(single.global_rotations[0], batch.global_rotations[index])
    assert batch.vertices is None


def test_dtype_follows_the_module_and_numpy_inputs_are_accepted() -> None:
    model = BuiltinHandModel(RIGHT, dtype=torch.float64)
    out = model(*(t.numpy() for t in _zeros(2)))
    assert out.joints.dtype == torch.float64 and out.joints.shape == (2, NUM_JOINTS, 3)
    assert out.global_rotations.shape == (2, 16, 3, 3)


@pytest.mark.parametrize(('index', 'value', 'message'), [
    (0, torch.zeros(3), r'global_orient: expected shape \(B, 3\), got \(3,\); add a batch axis'),
    (1, torch.zeros(2, 45), r'hand_pose: expected shape \(B, 15, 3\) .*reshape it with '
                            r'\.view\(2, 15, 3\)'),
    (2, torch.zeros(3, NUM_BETAS), r'betas: expected shape \(B, 10\) with B = 2 .*got \(3, 10\)'),
    (3, torch.zeros(2, 2), r'transl: expected shape \(B, 3\)'),
    (3, torch.zeros(2, 3, dtype=torch.long), r'transl: expected a floating-point tensor'),
])
def test_wrong_inputs_raise_input_error(index: int, value: torch.Tensor, message: str) -> None:
    inputs = list(_zeros(2))
    inputs[index] = value
    with pytest.raises(InputError, match=message):
        BuiltinHandModel(RIGHT)(*inputs)


def test_wrong_side_is_rejected() -> None:
    with pytest.raises(ValueError, match='hand side must be 0 .left. or 1 .right., got 2'):
        BuiltinHandModel(2)
