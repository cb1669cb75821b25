"""Tests of train/losses/depth_loss.py: confidence-weighted depth regression over valid pixels."""

import math

from infinihand_ros.core.errors import InputError
from infinihand_ros.train.losses import depth_losses
from infinihand_ros.train.losses import LossConfig
from loss_builders import assert_zero_with_finite_grad
import pytest
import torch


def _example() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Two samples of one 1x3 frame; kappa 2 and 0.5; unknown (0) and NaN targets included."""
    pred = torch.tensor([[[[1.0, 2.0, 5.0]]], [[[1.0, 1.0, 1.0]]]], dtype=torch.float64)
    conf = torch.tensor([[[[1.0, 2.0, 3.0]]], [[[4.0, 1.0, 1.0]]]], dtype=torch.float64)
    target = torch.tensor([[[[2.0, 2.0, 0.0]]], [[[1.5, float('nan'), 1.0]]]],
                          dtype=torch.float64)
    return pred, conf, target, torch.tensor([2.0, 0.5], dtype=torch.float64)


def test_hand_computed_values(config: LossConfig) -> None:
    """Valid pixels: (1,1,2), (2,2,2), (1,4,1.5), (1,1,1) as (pred, conf, target).

    Per pixel c |d - d*| / kappa - alpha log c with alpha 0.3:
    1 * 1 / 2 - 0; 2 * 0 - 0.3 log 2; 4 * 0.5 / 0.5 - 0.3 log 4; 0 - 0.
    """
    pred, conf, target, kappa = _example()
    result = depth_losses(pred, conf, target, kappa, config=config)
    expected = (0.5 - 0.3 * math.log(2.0) + 4.0 - 0.3 * math.log(4.0)) / 4.0
    assert result.regression.item() == pytest.approx(expected, rel=1e-12)
    assert result.total.item() == pytest.approx(2.5 * expected, rel=1e-12)


def test_gradient_reaches_depth_and_confidence(config: LossConfig) -> None:
    """d/d pred of pixel (1, 1, 2) is c sign(d - d*) / (kappa N) = -1 / 8 before the weight."""
    pred, conf, target, kappa = _example()
    pred.requires_grad_(True)
    conf.requires_grad_(True)
    result = depth_losses(pred, conf, target, kappa, config=config)
    result.regression.backward()
    assert pred.grad[0, 0, 0, 0].item() == pytest.approx(-1.0 / 8.0)
    assert pred.grad[0, 0, 0, 2].item() == 0.0  # unknown target
    # d/dc of pixel (2, 2, 2): |d - d*| / kappa - alpha / c = -0.15, over N = 4.
    assert conf.grad[0, 0, 0, 1].item() == pytest.approx(-0.15 / 4.0)


def test_empty_valid_set_is_exactly_zero(config: LossConfig) -> None:
    """All targets unknown: 0.0 and zero, finite gradients."""
    pred, conf, target, kappa = _example()
    pred.requires_grad_(True)
    result = depth_losses(pred, conf, torch.zeros_like(target), kappa, config=config)
    assert_zero_with_finite_grad(result.total, pred)


def test_mismatched_shapes_are_refused(config: LossConfig) -> None:
    """A target of another size names the argument."""
    pred, conf, target, kappa = _example()
    with pytest.raises(InputError, match='depth target'):
        depth_losses(pred, conf, target[..., :2], kappa, config=config)
