"""Mask loss L_mask (paper Sec. 3.2 and appendix B.1): BCE from logits plus soft Dice.

For one valid hand mask of P pixels, with M_hat = sigmoid(logits):

    l_BCE  = -(1/P) sum_p [M_p log M_hat_p + (1 - M_p) log(1 - M_hat_p)]   (from the logits)
    l_Dice = 1 - (2 sum_p M_hat_p M_p + 1) / (sum_p M_hat_p + sum_p M_p + 1)

Each is averaged over the valid masks of the batch (pooled: every valid mask weighs the same,
whatever its sample), and ``L_mask = lambda_BCE L_BCE + lambda_Dice L_Dice``. A mask is valid
where its per-hand flag says the annotation exists (so a valid all-zero mask supervises "no
hand here", and a missing annotation gives no false negatives) and every target pixel is finite.
"""

from infinihand_ros.train.losses.loss_config import LossConfig
from infinihand_ros.train.losses.primitives import check_like
from infinihand_ros.train.losses.primitives import check_mask
from infinihand_ros.train.losses.primitives import finite_or_zero
from infinihand_ros.train.losses.primitives import finite_rows
from infinihand_ros.train.losses.primitives import masked_mean
from infinihand_ros.train.losses.primitives import promote
from infinihand_ros.train.losses.terms import MaskLosses
import torch
import torch.nn.functional as F


def mask_valid_set(target: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Return the (...) masks in the valid set: flagged valid and every target pixel finite.

    Args:
        target: (..., H, W) target masks.
        valid: (...) bool per-hand flags.

    """
    return valid & finite_rows(target, dims=2)


def per_mask_errors(logits: torch.Tensor, target: torch.Tensor
                    ) -> tuple[torch.Tensor, torch.Tensor]:
    """Return the per-mask l_BCE and l_Dice, both (...), of logits and targets (..., H, W)."""
    bce = F.binary_cross_entropy_with_logits(logits, target, reduction='none')
    probability = torch.sigmoid(logits)
    overlap = (probability * target).sum(dim=(-2, -1))
    dice = 1.0 - (2.0 * overlap + 1.0) / (
        probability.sum(dim=(-2, -1)) + target.sum(dim=(-2, -1)) + 1.0)
    return bce.mean(dim=(-2, -1)), dice


def mask_losses(logits: torch.Tensor, target: torch.Tensor, valid: torch.Tensor, *,
                config: LossConfig) -> MaskLosses:
    """Return L_BCE, L_Dice and L_mask over the valid hand masks.

    Args:
        logits: (B, S, 2, H, W) mask-head logits (before the sigmoid), side axis [left, right];
            any leading dims work as long as ``valid`` has them.
        target: (B, S, 2, H, W) target masks in [0, 1] (1 = hand), float or bool.
        valid: (B, S, 2) bool per-hand validity flags (annotation available).
        config: the loss config (``config.mask`` weights).

    Returns:
        ``MaskLosses`` with ``total = lambda_BCE bce + lambda_Dice dice``; every term is exactly
        0 when no mask is valid.

    Raises:
        InputError: for mismatched shapes or a non-bool ``valid``.

    """
    check_like('mask target', target, 'mask logits', logits)
    check_mask('mask valid', valid, logits.shape[:-2])
    logits, target = promote(logits, target)
    valid = mask_valid_set(target, valid)
    bce, dice = per_mask_errors(logits, finite_or_zero(target))
    bce_mean, dice_mean = masked_mean(bce, valid), masked_mean(dice, valid)
    weights = config.mask
    return MaskLosses(total=weights.bce_weight * bce_mean + weights.dice_weight * dice_mean,
                      bce=bce_mean, dice=dice_mean)
