"""Depth loss L_depth: not in the paper, the tiny model's stand-in for pretrained geometry.

The paper keeps LingBot-Map's pretrained depth head and trains no depth term. Our tiny model
starts from seeded weights, and the engine's metric scale compares hand depths with the depth
head's map, so the tiny configs supervise depth with VGGT's confidence-weighted regression:

    L_depth = mean over valid pixels of  c |d_hat - d| / kappa - alpha log c

with c >= 1 the predicted confidence, d the annotated depth (m), kappa the sample scale shared
with the camera and world terms (``anchoring.sample_scale``), and alpha
``losses.depth.confidence_alpha``. A pixel is valid where its target is finite and positive
(0 marks "nothing there", including letterbox padding) and the prediction is finite.
"""

from infinihand_ros.train.losses.loss_config import LossConfig
from infinihand_ros.train.losses.primitives import check_like
from infinihand_ros.train.losses.primitives import finite_or_zero
from infinihand_ros.train.losses.primitives import masked_mean
from infinihand_ros.train.losses.primitives import promote
from infinihand_ros.train.losses.terms import DepthLosses
import torch


def depth_losses(pred_depth: torch.Tensor, pred_confidence: torch.Tensor,
                 target_depth: torch.Tensor, scale: torch.Tensor, *,
                 config: LossConfig) -> DepthLosses:
    """Return L_depth over the valid pixels.

    Args:
        pred_depth: (B, S, H, W) predicted depth (m).
        pred_confidence: (B, S, H, W) predicted confidence (>= 1).
        target_depth: (B, S, H, W) annotated depth (m), 0 or non-finite where unknown.
        scale: (B,) kappa per sample, > 0.
        config: the loss config (``config.depth``).

    Returns:
        ``DepthLosses`` with ``total = lambda_depth regression``; exactly 0 without valid pixels.

    Raises:
        InputError: for mismatched shapes.

    """
    check_like('depth target', target_depth, 'predicted depth', pred_depth)
    check_like('depth confidence', pred_confidence, 'predicted depth', pred_depth)
    pred_depth, pred_confidence, target_depth = promote(pred_depth, pred_confidence,
                                                        target_depth)
    valid = (torch.isfinite(target_depth) & (target_depth > 0) & torch.isfinite(pred_depth)
             & torch.isfinite(pred_confidence) & (pred_confidence > 0))
    confidence = torch.where(valid, pred_confidence, torch.ones_like(pred_confidence))
    error = (finite_or_zero(pred_depth) - finite_or_zero(target_depth)).abs() \
        / scale.to(pred_depth.dtype)[:, None, None, None]
    per_pixel = confidence * error - config.depth.confidence_alpha * torch.log(confidence)
    regression = masked_mean(per_pixel, valid)
    return DepthLosses(total=config.depth.weight * regression, regression=regression)
