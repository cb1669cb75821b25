"""Tests of train/losses/landmark_loss.py: L1 in crop coordinates over the valid joints."""

from infinihand_ros.core.errors import InputError
from infinihand_ros.train.losses import landmark_losses
from infinihand_ros.train.losses import LossConfig
from loss_builders import assert_zero_with_finite_grad
import pytest
import torch

NAN = float('nan')


def _example() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Return predictions at 0, targets and flags (1, 1, 2, 21, 2) with every exclusion case."""
    pred = torch.zeros(1, 1, 2, 21, 2, dtype=torch.float64)
    target = torch.zeros_like(pred)
    valid = torch.zeros(1, 1, 2, 21, dtype=torch.bool)
    target[0, 0, 0, 0] = torch.tensor([0.5, -0.25])   # kept: 0.75
    target[0, 0, 0, 1] = torch.tensor([-1.0, 1.0])    # on the crop edge, kept: 2.0
    target[0, 0, 0, 2] = torch.tensor([NAN, 0.0])     # non-finite: excluded
    target[0, 0, 0, 3] = torch.tensor([1.5, 0.0])     # out of range: excluded
    target[0, 0, 1, 0] = torch.tensor([0.1, 0.1])     # missing (flag False): excluded
    valid[0, 0, 0, :4] = True
    return pred, target, valid


def test_hand_computed_value(config: LossConfig) -> None:
    """(|0.5| + |-0.25| + |-1| + |1|) / 2 valid joints = 1.375; total = 0.5 * 1.375."""
    pred, target, valid = _example()
    result = landmark_losses(pred, target, valid, config=config)
    assert result.l1.item() == pytest.approx(1.375, rel=1e-12)
    assert result.total.item() == pytest.approx(0.5 * 1.375, rel=1e-12)


def test_empty_valid_set_is_exactly_zero_with_finite_gradient(config: LossConfig) -> None:
    """Only excluded targets left: exactly 0 and a finite zero gradient."""
    pred, target, valid = _example()
    valid[0, 0, 0, :2] = False
    pred.requires_grad_(True)
    result = landmark_losses(pred, target, valid, config=config)
    assert result.l1.item() == 0.0
    assert_zero_with_finite_grad(result.total, pred)


def test_gradcheck(config: LossConfig) -> None:
    """Gradients match finite differences (float64)."""
    generator = torch.Generator().manual_seed(1)
    pred = torch.rand(1, 2, 2, 21, 2, dtype=torch.float64, generator=generator) * 2 - 1
    target = torch.rand(1, 2, 2, 21, 2, dtype=torch.float64, generator=generator) * 2 - 1
    valid = torch.rand(1, 2, 2, 21, generator=generator) > 0.3
    pred.requires_grad_(True)
    assert torch.autograd.gradcheck(
        lambda x: landmark_losses(x, target, valid, config=config).total, (pred,))


def test_wrong_joint_count_is_refused(config: LossConfig) -> None:
    """20 joints: InputError naming the prediction and the expected layout."""
    with pytest.raises(InputError, match=r'landmark pred: expected shape \(1, 1, 2, 21, 2\)'):
        landmark_losses(torch.zeros(1, 1, 2, 20, 2), torch.zeros(1, 1, 2, 20, 2),
                        torch.ones(1, 1, 2, 20, dtype=torch.bool), config=config)
