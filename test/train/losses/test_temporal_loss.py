"""Tests of train/losses/temporal_loss.py: predicted vs annotated frame-to-frame change."""

import math

from infinihand_ros.core.errors import InputError
from infinihand_ros.train.losses import LossConfig
from infinihand_ros.train.losses import temporal_camera_loss
from infinihand_ros.train.losses import temporal_landmark_loss
from infinihand_ros.train.losses import temporal_losses
from infinihand_ros.train.losses import temporal_mano_loss
from infinihand_ros.train.losses import temporal_mask_loss
from loss_builders import assert_zero_with_finite_grad
import pytest
import torch

NAN = float('nan')


def _camera_inputs() -> dict[str, torch.Tensor]:
    """Return a static annotated camera, predictions jumping 0.9 in x at frame 1; frame 2 off."""
    pred = torch.tensor([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
                        dtype=torch.float64).repeat(1, 3, 1)
    pred[0, 1:, 0] = 0.9
    return {'pred_pose_encoding': pred,
            'target_T_world_cam': torch.eye(4, dtype=torch.float64).repeat(1, 3, 1, 1),
            'target_fov': torch.ones(1, 3, 2, dtype=torch.float64),
            'camera_valid': torch.tensor([[True, True, False]]),
            'scale': torch.ones(1, dtype=torch.float64)}


def _mano_inputs() -> dict[str, torch.Tensor]:
    """Return one hand over two frames (orientation about z, betas and translation)."""
    zeros = {'global_orient': (3,), 'hand_pose': (15, 3), 'betas': (10,), 'transl': (3,)}
    inputs = {f'{side}_{key}': torch.zeros(1, 2, 1, *shape, dtype=torch.float64)
              for side in ('pred', 'target') for key, shape in zeros.items()}
    inputs['pred_global_orient'][0, :, 0, 2] = torch.tensor([0.1, 0.4], dtype=torch.float64)
    inputs['target_global_orient'][0, :, 0, 2] = torch.tensor([0.0, 0.2], dtype=torch.float64)
    inputs['target_betas'][0, 1, 0, 0] = 1.0
    inputs['pred_transl'][0, 1, 0, 0] = 0.3
    inputs['mano_valid'] = torch.ones(1, 2, 1, dtype=torch.bool)
    return inputs


def test_camera_part(config: LossConfig) -> None:
    """Residual change (0.9, 0, ..., 0) / 9 coordinates over the one valid pair."""
    assert temporal_camera_loss(**_camera_inputs()).item() == pytest.approx(0.1, rel=1e-12)
    no_pair = temporal_camera_loss(**_camera_inputs(), consecutive=torch.tensor([[False, True]]))
    assert no_pair.item() == 0.0


def test_mano_part(config: LossConfig) -> None:
    """Orientation steps 0.3 vs 0.2 rad; pose at the clamp floor; betas 1 / 10; transl 0.3 / 3."""
    expected = 0.1 + math.acos(1.0 - config.rotation_clamp_eps) + 0.1 + 0.1
    value = temporal_mano_loss(**_mano_inputs(), config=config)
    assert value.item() == pytest.approx(expected, rel=1e-9)


def test_mask_part() -> None:
    """The sigmoid of 0 is 0.5: against [1, 0] then [1, 1]: error change (0, -1), mean 0.5."""
    logits = torch.zeros(1, 3, 1, 1, 2, dtype=torch.float64)
    target = torch.tensor([[1.0, 0.0], [1.0, 1.0], [NAN, NAN]], dtype=torch.float64)
    target = target.reshape(1, 3, 1, 1, 2)
    valid = torch.tensor([[[True], [True], [False]]])
    assert temporal_mask_loss(logits=logits, target=target, valid=valid).item() == 0.5


def test_landmark_part(config: LossConfig) -> None:
    """Joint 0 moves (0.1, 0) while its target stays; joint 1 is valid in one frame only."""
    pred = torch.zeros(1, 2, 1, 21, 2, dtype=torch.float64)
    pred[0, 1, 0, 0, 0] = 0.1
    valid = torch.zeros(1, 2, 1, 21, dtype=torch.bool)
    valid[0, :, 0, 0] = True
    valid[0, 0, 0, 1] = True
    value = temporal_landmark_loss(pred=pred, target=torch.zeros_like(pred), valid=valid,
                                   config=config)
    assert value.item() == pytest.approx(0.1, rel=1e-12)


def test_weighting_and_missing_parts(config: LossConfig) -> None:
    """The total is lambda_temp (1 c + 2 m + 3 k + 4 l); None counts as 0; all None is refused."""
    parts = {'camera': torch.tensor(1.0), 'mano': torch.tensor(2.0), 'mask': None,
             'landmarks': torch.tensor(0.5)}
    result = temporal_losses(**parts, config=config)
    assert result.total.item() == 2.0 * (1.0 + 4.0 + 0.0 + 2.0)
    assert result.mask.item() == 0.0
    with pytest.raises(InputError, match='every part is None'):
        temporal_losses(camera=None, mano=None, mask=None, landmarks=None, config=config)


def test_empty_valid_sets_are_exactly_zero_with_finite_gradient(config: LossConfig) -> None:
    """Every part with no valid pair (NaN targets behind False flags) is 0 with finite grads."""
    camera = _camera_inputs() | {'camera_valid': torch.tensor([[True, False, True]])}
    camera['pred_pose_encoding'].requires_grad_(True)
    assert_zero_with_finite_grad(temporal_camera_loss(**camera), camera['pred_pose_encoding'])
    mano = _mano_inputs()
    mano['mano_valid'] = torch.tensor([[[True], [False]]])
    for key in ('global_orient', 'hand_pose', 'betas', 'transl'):
        mano[f'target_{key}'][:, 1] = NAN
        mano[f'pred_{key}'] = torch.zeros_like(mano[f'pred_{key}'], requires_grad=True)
    assert_zero_with_finite_grad(temporal_mano_loss(**mano, config=config),
                                 *(mano[f'pred_{key}'] for key in ('global_orient', 'hand_pose',
                                                                   'betas', 'transl')))
    logits = torch.zeros(1, 2, 2, 3, 3, dtype=torch.float64, requires_grad=True)
    mask = temporal_mask_loss(logits=logits, target=torch.full_like(logits, NAN),
                              valid=torch.ones(1, 2, 2, dtype=torch.bool))
    assert_zero_with_finite_grad(mask, logits)
    pred = torch.zeros(1, 2, 2, 21, 2, dtype=torch.float64, requires_grad=True)
    landmarks = temporal_landmark_loss(pred=pred, target=torch.full_like(pred, 3.0),
                                       valid=torch.ones(1, 2, 2, 21, dtype=torch.bool),
                                       config=config)
    assert_zero_with_finite_grad(landmarks, pred)


def test_gradcheck(config: LossConfig) -> None:
    """Gradients of every part match finite differences (float64, random inputs)."""
    generator = torch.Generator().manual_seed(5)

    def rand(*shape: int) -> torch.Tensor:
        return torch.randn(*shape, dtype=torch.float64, generator=generator)

    camera = _camera_inputs()
    encoding = (camera.pop('pred_pose_encoding') + 0.1 * rand(1, 3, 9)).requires_grad_(True)
    assert torch.autograd.gradcheck(
        lambda x: temporal_camera_loss(pred_pose_encoding=x, **camera), (encoding,))
    mano = _mano_inputs()
    keys = ('global_orient', 'hand_pose', 'betas', 'transl')
    preds = tuple((mano.pop(f'pred_{key}') + 0.3 * rand(*mano[f'target_{key}'].shape))
                  .requires_grad_(True) for key in keys)
    assert torch.autograd.gradcheck(lambda *p: temporal_mano_loss(
        **dict(zip((f'pred_{key}' for key in keys), p)), **mano, config=config), preds)
    logits = rand(1, 3, 2, 2, 2).requires_grad_(True)
    target = (rand(1, 3, 2, 2, 2) > 0).double()
    valid = torch.ones(1, 3, 2, dtype=torch.bool)
    assert torch.autograd.gradcheck(
        lambda x: temporal_mask_loss(logits=x, target=target, valid=valid), (logits,))
    pred = (0.5 * rand(1, 3, 2, 21, 2)).requires_grad_(True)
    target_2d = 0.5 * rand(1, 3, 2, 21, 2)
    valid_2d = torch.ones(1, 3, 2, 21, dtype=torch.bool)
    assert torch.autograd.gradcheck(lambda x: temporal_landmark_loss(
        pred=x, target=target_2d, valid=valid_2d, config=config), (pred,))
