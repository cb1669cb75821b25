"""Tests of train/losses/mask_loss.py: BCE from logits and soft Dice over valid masks."""

import math

from infinihand_ros.core.errors import InputError
from infinihand_ros.train.losses import LossConfig
from infinihand_ros.train.losses import mask_losses
from loss_builders import assert_zero_with_finite_grad
import pytest
import torch


def _example() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Return logits, targets (1, 1, 3, 2, 2) and flags: two valid masks and a NaN one."""
    log3 = math.log(3.0)
    logits = torch.tensor([[[[log3, 0.0], [0.0, -log3]],
                            [[0.0, 0.0], [0.0, 0.0]],
                            [[5.0, -5.0], [1.0, 2.0]]]], dtype=torch.float64)[None]
    target = torch.tensor([[[[1.0, 0.0], [0.0, 0.0]],
                            [[0.0, 0.0], [0.0, 0.0]],
                            [[float('nan'), 1.0], [1.0, 1.0]]]], dtype=torch.float64)[None]
    return logits, target, torch.tensor([[[True, True, True]]])


def test_hand_computed_values(config: LossConfig) -> None:
    """Probabilities (.75, .5, .5, .25) and (.5, .5, .5, .5); the NaN mask leaves the set.

    Mask 1: BCE = (2 log(4/3) + 2 log 2) / 4, Dice = 1 - (2 * .75 + 1) / (2 + 1 + 1) = .375.
    Mask 2 (empty target, valid): BCE = log 2, Dice = 1 - 1 / (2 + 0 + 1) = 2/3.
    """
    logits, target, valid = _example()
    result = mask_losses(logits, target, valid, config=config)
    bce = (math.log(8.0 / 3.0) / 2.0 + math.log(2.0)) / 2.0
    dice = (0.375 + 2.0 / 3.0) / 2.0
    assert result.bce.item() == pytest.approx(bce, rel=1e-12)
    assert result.dice.item() == pytest.approx(dice, rel=1e-12)
    assert result.total.item() == pytest.approx(2.0 * bce + 3.0 * dice, rel=1e-12)


def test_invalid_flags_drop_masks_and_bool_targets_work(config: LossConfig) -> None:
    """Only mask 2 flagged: BCE log 2 and Dice 2/3; a bool target gives the same."""
    logits, target, _ = _example()
    valid = torch.tensor([[[False, True, False]]])
    result = mask_losses(logits, target, valid, config=config)
    assert result.bce.item() == pytest.approx(math.log(2.0))
    assert result.dice.item() == pytest.approx(2.0 / 3.0)
    as_bool = mask_losses(logits, torch.nan_to_num(target) > 0.5, valid, config=config)
    torch.testing.assert_close(as_bool.total, result.total)


def test_empty_valid_set_is_exactly_zero_with_finite_gradient(config: LossConfig) -> None:
    """No valid mask (and NaN targets behind the flags): 0.0 and zero, finite gradients."""
    logits, target, _ = _example()
    logits.requires_grad_(True)
    result = mask_losses(logits, torch.full_like(target, float('nan')),
                         torch.zeros(1, 1, 3, dtype=torch.bool), config=config)
    for term in (result.bce, result.dice):
        assert term.item() == 0.0
    assert_zero_with_finite_grad(result.total, logits)


def test_gradcheck(config: LossConfig) -> None:
    """Gradients of L_mask match finite differences (float64, small masks)."""
    generator = torch.Generator().manual_seed(0)
    logits = torch.randn(1, 2, 2, 3, 3, dtype=torch.float64, generator=generator)
    target = (torch.rand(1, 2, 2, 3, 3, generator=generator) > 0.5).double()
    valid = torch.tensor([[[True, False], [True, True]]])
    logits.requires_grad_(True)
    assert torch.autograd.gradcheck(
        lambda x: mask_losses(x, target, valid, config=config).total, (logits,))


def test_shape_errors_name_the_inputs(config: LossConfig) -> None:
    """A mismatched target or flag array raises InputError naming it."""
    logits = torch.zeros(1, 1, 2, 4, 4)
    with pytest.raises(InputError, match='mask target: expected the shape of mask logits'):
        mask_losses(logits, torch.zeros(1, 1, 2, 4, 3), torch.ones(1, 1, 2, dtype=torch.bool),
                    config=config)
    with pytest.raises(InputError, match=r'mask valid: expected shape \(1, 1, 2\)'):
        mask_losses(logits, torch.zeros(1, 1, 2, 4, 4), torch.ones(1, 2, dtype=torch.bool),
                    config=config)
