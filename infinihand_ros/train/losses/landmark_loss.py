"""2D landmark loss L_2D (paper Sec. 3.2 and appendix B.1): L1 in normalised crop coordinates.

Per valid joint the error is ``||p_hat - p||_1 = |dx| + |dy|`` (no 1/2: appendix B keeps its
coordinate factors explicit and writes none here), averaged over the valid joints of the batch.
Coordinates are grid_sample's ``align_corners=False`` ones over the canonical (left hands
mirrored) square crop, -1 and 1 at its outer pixel edges, as the landmark head predicts them.
The valid set excludes missing (flag False), non-finite and out-of-range targets (|x| or |y|
above ``landmarks.max_abs``, i.e. outside the crop by default).
"""

from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.train.losses.loss_config import LossConfig
from infinihand_ros.train.losses.primitives import check_like
from infinihand_ros.train.losses.primitives import check_mask
from infinihand_ros.train.losses.primitives import check_shape
from infinihand_ros.train.losses.primitives import finite_or_zero
from infinihand_ros.train.losses.primitives import finite_rows
from infinihand_ros.train.losses.primitives import masked_mean
from infinihand_ros.train.losses.primitives import promote
from infinihand_ros.train.losses.terms import LandmarkLosses
import torch


def landmark_valid_set(target: torch.Tensor, valid: torch.Tensor,
                       max_abs: float) -> torch.Tensor:
    """Return the (...) joints in the L_2D valid set.

    Args:
        target: (..., 2) target landmarks, normalised crop coordinates.
        valid: (...) bool flags (the annotation exists).
        max_abs: largest |x| and |y| still in range.

    """
    in_range = (finite_or_zero(target).abs() <= max_abs).all(dim=-1)
    return valid & finite_rows(target) & in_range


def landmark_losses(pred: torch.Tensor, target: torch.Tensor, valid: torch.Tensor, *,
                    config: LossConfig) -> LandmarkLosses:
    """Return L_2D over the valid joints.

    Args:
        pred: (B, S, 2, 21, 2) predicted landmarks (x, y), normalised canonical crop coordinates,
            OpenPose joint order, side axis [left, right]; any leading dims work.
        target: (B, S, 2, 21, 2) targets in the same crops and coordinates.
        valid: (B, S, 2, 21) bool, True where the target joint is annotated.
        config: the loss config (``config.landmarks``).

    Returns:
        ``LandmarkLosses`` with ``total = lambda_2D l1``; exactly 0 with no valid joint.

    Raises:
        InputError: for mismatched shapes or a non-bool ``valid``.

    """
    check_shape('landmark pred', pred, (*pred.shape[:-2], NUM_JOINTS, 2))
    check_like('landmark target', target, 'landmark pred', pred)
    check_mask('landmark valid', valid, pred.shape[:-1])
    pred, target = promote(pred, target)
    valid = landmark_valid_set(target, valid, config.landmarks.max_abs)
    error = (pred - finite_or_zero(target)).abs().sum(dim=-1)
    l1 = masked_mean(error, valid)
    return LandmarkLosses(total=config.landmarks.weight * l1, l1=l1)
