"""Tests of train/losses/mano_loss.py: the six camera-space MANO terms."""

import math

from infinihand_ros.core.errors import InputError
from infinihand_ros.train.losses import LossConfig
from infinihand_ros.train.losses import mano_losses
from infinihand_ros.train.losses.mano_loss import project_normalized
from loss_builders import assert_zero_with_finite_grad
import pytest
import torch

NAN = float('nan')
#: fx = fy = 100 px, principal point (50, 40), for a 100 x 80 (W x H) image.
K = torch.tensor([[100.0, 0.0, 50.0], [0.0, 100.0, 40.0], [0.0, 0.0, 1.0]], dtype=torch.float64)
IMAGE_SIZE = (80, 100)


def _vector(*values: float) -> torch.Tensor:
    """Return a float64 vector (float32 literals would be off by 1e-8)."""
    return torch.tensor(values, dtype=torch.float64)


def _example() -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor]]:
    """Return predictions and targets (B = S = 1); hand 0 annotated, hand 1 not (NaN targets)."""
    shapes = {'global_orient': (3,), 'hand_pose': (15, 3), 'betas': (10,), 'transl': (3,),
              'joints_cam': (21, 3)}
    pred = {key: torch.zeros(1, 1, 2, *shape, dtype=torch.float64)
            for key, shape in shapes.items()}
    target = {key: torch.full_like(value, NAN) for key, value in pred.items()}
    target['joints_2d'] = torch.full((1, 1, 2, 21, 2), NAN, dtype=torch.float64)
    pred['global_orient'][..., 0, :] = _vector(0.0, 0.0, 0.3)
    target['global_orient'][..., 0, :] = _vector(0.0, 0.0, -0.2)
    pred['hand_pose'][..., 0, 0, :] = _vector(0.6, 0.0, 0.0)
    target['hand_pose'][..., 0, :, :] = 0.0
    target['betas'][..., 0, :] = _vector(1.0, 2.0, *[0.0] * 8)
    pred['transl'][..., 0, :] = _vector(0.1, 0.2, 0.5)
    target['transl'][..., 0, :] = _vector(0.0, 0.0, 0.3)
    # Predicted joints project to (60, 30) px; the 2D targets sit 10 px right and 4 px down.
    pred['joints_cam'][..., :, :] = _vector(0.05, -0.05, 0.5)
    target['joints_cam'][..., 0, :, :] = _vector(0.08, -0.05, 0.5)
    target['joints_cam'][..., 0, 20, :] = NAN      # non-finite 3D target: out of L_joints only
    target['joints_cam'][..., 0, 19, :] = 1.0      # flagged missing below
    target['joints_2d'][..., 0, :, :] = _vector(70.0, 34.0)
    return pred, target


def _call(pred: dict[str, torch.Tensor], target: dict[str, torch.Tensor], config: LossConfig,
          mano_valid: torch.Tensor | None = None, joints_valid: torch.Tensor | None = None):
    """Run mano_losses with hand 0 and its joints but 19 flagged valid unless told otherwise."""
    if mano_valid is None:
        mano_valid = torch.tensor([[[True, False]]])
    if joints_valid is None:
        joints_valid = torch.zeros(1, 1, 2, 21, dtype=torch.bool)
        joints_valid[0, 0, 0] = True
        joints_valid[0, 0, 0, 19] = False
    return mano_losses(
        **{f'pred_{key}': value for key, value in pred.items()},
        **{f'target_{key}': value for key, value in target.items()},
        intrinsics=K.expand(1, 1, 3, 3), image_size=IMAGE_SIZE, mano_valid=mano_valid,
        joints_valid=joints_valid, config=config)


def test_hand_computed_values(config: LossConfig) -> None:
    """Each term against its appendix-B formula, worked by hand.

    orient: same axis, 0.3 vs -0.2 -> 0.5 rad. pose: one joint off by 0.6 rad, 14 identical
    ones at the clamp floor arccos(1 - eps). shape: (1 + 4) / 10. trans: (.01 + .04 + .04) / 3.
    joints: |0.03| / 3 over 19 joints (20 is NaN, 19 flagged off). reproj: 2 * 10 / 100 +
    2 * 4 / 80 over 20 joints (joint 20 still has a 2D target).
    """
    result = _call(*_example(), config)
    floor = math.acos(1.0 - config.rotation_clamp_eps)
    expected = {'orient': 0.5, 'pose': (0.6 + 14 * floor) / 15, 'shape': 0.5, 'trans': 0.03,
                'joints': 0.01, 'reproj': 0.3}
    for key, value in expected.items():
        assert getattr(result, key).item() == pytest.approx(value, rel=1e-9), key
    weights = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    total = sum(w * v for w, v in zip(weights, expected.values()))
    assert result.total.item() == pytest.approx(total, rel=1e-9)


def test_projection_floors_the_depth() -> None:
    """A joint behind the camera projects as if at 1 cm: x / z = 0.1 -> u = 60 px."""
    point = torch.tensor([0.001, 0.0, -0.5], dtype=torch.float64).expand(1, 1, 2, 21, 3)
    projected = project_normalized(point, K.expand(1, 1, 3, 3), IMAGE_SIZE, 0.01)
    torch.testing.assert_close(projected[0, 0, 0, 0],
                               torch.tensor([121 / 100 - 1, 81 / 80 - 1], dtype=torch.float64))


def test_empty_valid_set_is_exactly_zero_with_finite_gradient(config: LossConfig) -> None:
    """No flag set, NaN targets, zero rotations and joints at depth 0: zeros, finite grads."""
    pred, target = _example()
    pred = {key: torch.zeros_like(value, requires_grad=True) for key, value in pred.items()}
    target = {key: torch.full_like(value, NAN) for key, value in target.items()}
    result = _call(pred, target, config, mano_valid=torch.zeros(1, 1, 2, dtype=torch.bool),
                   joints_valid=torch.zeros(1, 1, 2, 21, dtype=torch.bool))
    for key in ('orient', 'pose', 'shape', 'trans', 'joints', 'reproj'):
        assert getattr(result, key).item() == 0.0
    assert_zero_with_finite_grad(result.total, *pred.values())


def test_gradcheck(config: LossConfig) -> None:
    """Gradients wrt every prediction match finite differences (float64, random hands)."""
    generator = torch.Generator().manual_seed(2)

    def rand(*shape: int) -> torch.Tensor:
        return torch.randn(*shape, dtype=torch.float64, generator=generator)

    pred = {'global_orient': rand(1, 1, 2, 3), 'hand_pose': 0.5 * rand(1, 1, 2, 15, 3),
            'betas': rand(1, 1, 2, 10), 'transl': rand(1, 1, 2, 3),
            'joints_cam': 0.05 * rand(1, 1, 2, 21, 3) + torch.tensor([0.0, 0.0, 0.5])}
    target = {key: value + 0.3 * rand(*value.shape) for key, value in pred.items()}
    target['joints_2d'] = 50.0 + 10.0 * rand(1, 1, 2, 21, 2)
    joints_valid = torch.rand(1, 1, 2, 21, generator=generator) > 0.2
    names = list(pred)

    def total(*values: torch.Tensor) -> torch.Tensor:
        return _call(dict(zip(names, values)), target, config,
                     mano_valid=torch.tensor([[[True, True]]]), joints_valid=joints_valid).total

    inputs = tuple(value.requires_grad_(True) for value in pred.values())
    assert torch.autograd.gradcheck(total, inputs)


def test_shape_errors_name_the_inputs(config: LossConfig) -> None:
    """A 16-joint hand pose or per-hand intrinsics raise InputError naming the argument."""
    pred, target = _example()
    pred['hand_pose'] = torch.zeros(1, 1, 2, 16, 3, dtype=torch.float64)
    with pytest.raises(InputError, match=r'pred_hand_pose: expected shape \(1, 1, 2, 15, 3\)'):
        _call(pred, target, config)
    pred, target = _example()
    with pytest.raises(InputError, match=r'intrinsics: expected shape \(1, 1, 3, 3\)'):
        mano_losses(**{f'pred_{key}': value for key, value in pred.items()},
                    **{f'target_{key}': value for key, value in target.items()},
                    intrinsics=K.expand(1, 1, 2, 3, 3), image_size=IMAGE_SIZE,
                    mano_valid=torch.ones(1, 1, 2, dtype=torch.bool),
                    joints_valid=torch.ones(1, 1, 2, 21, dtype=torch.bool), config=config)
