"""Tests of train/losses/world_joint_loss.py: rho_eps on anchored, kappa-normalised joints."""

import math

from infinihand_ros.core.errors import InputError
from infinihand_ros.train.losses import LossConfig
from infinihand_ros.train.losses import world_joint_losses
from loss_builders import assert_zero_with_finite_grad
from loss_builders import rigid
from loss_builders import rotation_x
from loss_builders import rotation_z
import pytest
import torch

ANCHOR = rigid(rotation_x(0.7), (1.0, 2.0, 3.0))


def _example() -> dict[str, torch.Tensor]:
    """Return the inputs of a two-frame clip; hand 0 annotated, hand 1 not.

    Predicted poses: identity, then [Rz(90 deg) | (0.1, 0, 0)]; every predicted camera joint at
    (0.1, 0, 0.4), so the predicted world joints are (0.1, 0, 0.4) and (0.1, 0.1, 0.4). Targets
    in the anchor frame: (0.1, 0, 0.4) and (0.12, 0.1, 0.3), given in a dataset world whose
    anchor camera is [Rx(0.7) | (1, 2, 3)].
    """
    pred_poses = torch.stack([torch.eye(4, dtype=torch.float64),
                              rigid(rotation_z(math.pi / 2), (0.1, 0.0, 0.0))])[None]
    anchored = torch.zeros(1, 2, 2, 21, 3, dtype=torch.float64)
    anchored[0, 0] = torch.tensor([0.1, 0.0, 0.4], dtype=torch.float64)
    anchored[0, 1] = torch.tensor([0.12, 0.1, 0.3], dtype=torch.float64)
    target = anchored @ ANCHOR[:3, :3].T + ANCHOR[:3, 3]
    target[:, :, 1] = float('nan')
    target[0, 1, 0, 20, 0] = float('nan')   # one non-finite coordinate leaves N_J
    return {
        'pred_joints_cam': torch.tensor([0.1, 0.0, 0.4], dtype=torch.float64).repeat(
            1, 2, 2, 21, 1),
        'pred_T_world_cam': pred_poses,
        'target_joints_world': target,
        'target_T_world_cam': torch.stack([ANCHOR, ANCHOR @ rigid(rotation_z(0.2),
                                                                  (0.0, 0.0, 1.0))])[None],
        'hand_valid': torch.tensor([[[True, False], [True, False]]]),
        'camera_valid': torch.tensor([[True, True]]),
        'scale': torch.tensor([2.0], dtype=torch.float64),
    }


def test_hand_computed_value(config: LossConfig) -> None:
    """Frame 1 residual / kappa = (-0.01, 0, 0.05): rho_0.02 = 0.0025, 0, 0.05 - 0.01.

    Frame 0 matches exactly. N_J = 63 + 62 valid coordinates (hand 1 and one NaN left out).
    """
    result = world_joint_losses(**_example(), config=config)
    expected = (21 * (0.0025 + 0.04) - 0.0025) / 125
    assert result.joints.item() == pytest.approx(expected, rel=1e-9)
    assert result.total.item() == pytest.approx(1.5 * expected, rel=1e-9)


def test_missing_anchor_or_hands_give_exactly_zero(config: LossConfig) -> None:
    """No frame-0 camera annotation (no anchor) or no valid hand: 0 with finite zero grads."""
    for changes in ({'camera_valid': torch.tensor([[False, True]])},
                    {'hand_valid': torch.zeros(1, 2, 2, dtype=torch.bool)}):
        inputs = _example() | changes
        inputs['target_T_world_cam'] = torch.full_like(inputs['target_T_world_cam'],
                                                       float('nan'))
        inputs['target_joints_world'] = torch.full_like(inputs['target_joints_world'],
                                                        float('nan'))
        inputs['pred_joints_cam'].requires_grad_(True)
        inputs['pred_T_world_cam'].requires_grad_(True)
        result = world_joint_losses(**inputs, config=config)
        assert_zero_with_finite_grad(result.total, inputs['pred_joints_cam'],
                                     inputs['pred_T_world_cam'])


def test_gradcheck(config: LossConfig) -> None:
    """Gradients wrt predicted joints and poses match finite differences (float64)."""
    generator = torch.Generator().manual_seed(3)
    inputs = _example()
    inputs['target_joints_world'] = torch.randn(1, 2, 2, 21, 3, dtype=torch.float64,
                                                generator=generator)
    inputs['hand_valid'] = torch.tensor([[[True, False], [True, True]]])
    joints = (0.3 * torch.randn(1, 2, 2, 21, 3, dtype=torch.float64, generator=generator))
    poses = inputs.pop('pred_T_world_cam').clone()
    del inputs['pred_joints_cam']

    def total(joints_cam: torch.Tensor, pred_poses: torch.Tensor) -> torch.Tensor:
        return world_joint_losses(pred_joints_cam=joints_cam, pred_T_world_cam=pred_poses,
                                  **inputs, config=config).total

    assert torch.autograd.gradcheck(total, (joints.requires_grad_(True),
                                            poses.requires_grad_(True)))


def test_shape_errors_name_the_inputs(config: LossConfig) -> None:
    """A per-hand scale or a 3 x 4 pose raise InputError naming the argument."""
    with pytest.raises(InputError, match=r'scale: expected shape \(1\)'):
        world_joint_losses(**_example() | {'scale': torch.ones(1, 2)}, config=config)
    inputs = _example()
    inputs['pred_T_world_cam'] = inputs['pred_T_world_cam'][..., :3, :]
    with pytest.raises(InputError, match=r'pred_T_world_cam: expected shape \(1, 2, 4, 4\)'):
        world_joint_losses(**inputs, config=config)
