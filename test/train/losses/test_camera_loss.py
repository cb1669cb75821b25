"""Tests of train/losses/camera_loss.py: absolute and relative pose terms."""

import math

from infinihand_ros.core.errors import InputError
from infinihand_ros.train.losses import camera_losses
from infinihand_ros.train.losses import LossConfig
from loss_builders import assert_zero_with_finite_grad
from loss_builders import rigid
from loss_builders import rotation_x
from loss_builders import rotation_z
import pytest
import torch

NAN = float('nan')
ANCHOR = rigid(rotation_z(0.4), (1.0, 0.0, 0.0))


def _rho(residual: float, eps: float = 0.05) -> float:
    """Return rho_eps(residual) as appendix B writes it."""
    return residual ** 2 / (2 * eps) if abs(residual) < eps else abs(residual) - eps / 2


def _example() -> dict[str, torch.Tensor]:
    """Return a three-frame clip: frames 0, 1 annotated, frame 2 not (NaN), kappa = 2.

    Targets: C_0 = [Rz(0.4) | (1, 0, 0)], C_1 = C_0 [Rx(0.3) | (0.2, 0, 0)], FoV (0.9, 1.1).
    Predictions: frame 0 t = (0.04, 0, 0), q = -identity, FoV (0.9, 1.2); frame 1
    t = (0.2, 0, 0), q = Rx(0.5), FoV (0.9, 1.1).
    """
    poses = torch.stack([ANCHOR, ANCHOR @ rigid(rotation_x(0.3), (0.2, 0.0, 0.0)),
                         torch.full((4, 4), NAN, dtype=torch.float64)])[None]
    fov = torch.tensor([[[0.9, 1.1], [0.9, 1.1], [NAN, NAN]]], dtype=torch.float64)
    half = 0.25
    pred = torch.tensor([[[0.04, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.9, 1.2],
                          [0.2, 0.0, 0.0, math.sin(half), 0.0, 0.0, math.cos(half), 0.9, 1.1],
                          [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0]]], dtype=torch.float64)
    return {'pred_pose_encoding': pred, 'target_T_world_cam': poses, 'target_fov': fov,
            'camera_valid': torch.tensor([[True, True, False]]),
            'scale': torch.tensor([2.0], dtype=torch.float64)}


def test_hand_computed_values(config: LossConfig) -> None:
    """Absolute: frame 0 rho(0.02) + rho(0) (sign-aligned) + rho(0.1); frame 1 quaternion only.

    Relative, both ordered pairs: d_SO(3)(Rx(-+0.5), Rx(-+0.3)) = 0.2 plus
    lambda_rel,u * |0.08 - 0.1| (normalised relative translations).
    """
    result = camera_losses(**_example(), config=config)
    frame0 = _rho(0.02) + _rho(0.1)
    frame1 = _rho(math.sin(0.25) - math.sin(0.15)) + _rho(math.cos(0.25) - math.cos(0.15))
    abs_pose = (frame0 + frame1) / 18
    assert result.abs_pose.item() == pytest.approx(abs_pose, rel=1e-9)
    assert result.rel_pose.item() == pytest.approx(0.2 + 2.0 * 0.02, rel=1e-9)
    assert result.total.item() == pytest.approx(0.5 * (2.0 * abs_pose + 3.0 * 0.24), rel=1e-9)


def test_relative_term_needs_two_valid_frames_in_the_window(config: LossConfig) -> None:
    """W_pose without frame 1, or one valid frame: L_rel-pose is exactly 0."""
    outside = camera_losses(**_example(), config=config,
                            pose_window=torch.tensor([[True, False, True]]))
    assert outside.rel_pose.item() == 0.0
    single = camera_losses(**_example() | {'camera_valid': torch.tensor([[False, True, False]])},
                           config=config)
    assert single.rel_pose.item() == 0.0
    assert single.abs_pose.item() == 0.0   # frame 0, the anchor, is missing: no V_cam


def test_empty_valid_set_is_exactly_zero_with_finite_gradient(config: LossConfig) -> None:
    """No valid frame (and NaN targets everywhere): both terms 0 and finite zero gradients."""
    inputs = _example()
    inputs['target_T_world_cam'] = torch.full_like(inputs['target_T_world_cam'], NAN)
    inputs['camera_valid'] = torch.zeros(1, 3, dtype=torch.bool)
    inputs['pred_pose_encoding'].requires_grad_(True)
    result = camera_losses(**inputs, config=config)
    assert result.abs_pose.item() == 0.0
    assert result.rel_pose.item() == 0.0
    assert_zero_with_finite_grad(result.total, inputs['pred_pose_encoding'])


def test_gradcheck(config: LossConfig) -> None:
    """Gradients wrt the encodings match finite differences (float64, raw quaternions)."""
    generator = torch.Generator().manual_seed(4)
    inputs = _example()
    inputs['target_T_world_cam'][0, 2] = rigid(rotation_z(-0.7) @ rotation_x(1.0),
                                               (0.3, -0.2, 0.5))
    inputs['target_fov'][0, 2] = torch.tensor([1.0, 1.2])
    inputs['camera_valid'] = torch.tensor([[True, True, True]])
    pred = inputs.pop('pred_pose_encoding')
    pred = pred + 0.2 * torch.randn(pred.shape, dtype=torch.float64, generator=generator)

    def total(encoding: torch.Tensor) -> torch.Tensor:
        return camera_losses(pred_pose_encoding=encoding, **inputs, config=config).total

    assert torch.autograd.gradcheck(total, (pred.requires_grad_(True),))


def test_shape_errors_name_the_inputs(config: LossConfig) -> None:
    """A 7-number encoding or a non-bool window raise InputError naming the argument."""
    inputs = _example()
    with pytest.raises(InputError, match=r'pred_pose_encoding: expected shape \(\*, \*, 9\)'):
        camera_losses(**inputs | {'pred_pose_encoding': torch.zeros(1, 3, 7)}, config=config)
    with pytest.raises(InputError, match='pose_window: expected a bool validity mask'):
        camera_losses(**inputs, config=config, pose_window=torch.ones(1, 3))
