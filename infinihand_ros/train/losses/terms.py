"""Results of the loss groups and their sum L_joint (paper Sec. 3.3).

Each group function returns a frozen ``LossTerms`` subclass holding its unweighted terms and
``total``, the group's weighted contribution to

    L_joint = lambda_cam L_camera + lambda_w L_joints^w + lambda_temp L_temp + L_MANO
              + lambda_2D L_2D + L_mask,

so Stage I sums the groups it trains (mask, landmarks, MANO) and Stage II sums all six.
"""

from collections.abc import Iterable
import dataclasses
from dataclasses import dataclass

from infinihand_ros.core.errors import InputError
import torch


@dataclass(frozen=True)
class LossTerms:
    """Base of every group result: scalar tensors, ``total`` the weighted contribution.

    Attributes:
        total: the group's term of L_joint, weights included (scalar tensor).

    """

    total: torch.Tensor

    def named_terms(self, prefix: str = '') -> dict[str, torch.Tensor]:
        """Return ``{prefix + field name: scalar}`` for logging (tensors are not copied)."""
        return {prefix + item.name: getattr(self, item.name)
                for item in dataclasses.fields(self)}


@dataclass(frozen=True)
class MaskLosses(LossTerms):
    """L_mask (appendix B.1): ``total = lambda_BCE bce + lambda_Dice dice``.

    Attributes:
        bce: L_BCE, mean over valid masks of the per-mask pixel-mean BCE.
        dice: L_Dice, mean over valid masks of the soft Dice loss with +1 smoothing.

    """

    bce: torch.Tensor
    dice: torch.Tensor


@dataclass(frozen=True)
class DepthLosses(LossTerms):
    """L_depth (ours, not the paper's): ``total = lambda_depth regression``.

    Attributes:
        regression: mean over valid pixels of ``c |d_hat - d| / kappa - alpha log c``.

    """

    regression: torch.Tensor


@dataclass(frozen=True)
class LandmarkLosses(LossTerms):
    """L_2D (appendix B.1): ``total = lambda_2D l1``.

    Attributes:
        l1: mean over valid joints of |dx| + |dy| in normalised crop coordinates.

    """

    l1: torch.Tensor


@dataclass(frozen=True)
class ManoLosses(LossTerms):
    """L_MANO (Sec. 3.2, appendix B.2): ``total`` is the sum of the six weighted terms.

    Attributes:
        orient: L_orient, d_SO(3) of the camera-frame global orientation (rad).
        pose: L_pose, mean d_SO(3) over the 15 local joint rotations (rad).
        shape: L_shape, ||beta_hat - beta||^2 / 10.
        trans: L_trans, ||t_hat^c - t^c||^2 / 3 (m^2).
        joints: L_joints^c, ||J_hat^c - J^c||_1 / 3 per joint (m).
        reproj: L_reproj, L1 of the projected joints in normalised image coordinates.

    """

    orient: torch.Tensor
    pose: torch.Tensor
    shape: torch.Tensor
    trans: torch.Tensor
    joints: torch.Tensor
    reproj: torch.Tensor


@dataclass(frozen=True)
class WorldJointLosses(LossTerms):
    """L_joints^w (appendix B.3): ``total = lambda_w joints``.

    Attributes:
        joints: mean rho_eps over valid world-joint coordinates (kappa-normalised).

    """

    joints: torch.Tensor


@dataclass(frozen=True)
class CameraLosses(LossTerms):
    """L_camera (appendix B.3): ``total = lambda_cam (alpha_abs abs_pose + alpha_rel rel_pose)``.

    Attributes:
        abs_pose: L_abs-pose, rho_eps over the nine encoding coordinates / (9 |V_cam|).
        rel_pose: L_rel-pose, mean over valid ordered pairs of d_SO(3) + lambda_rel,u L1.

    """

    abs_pose: torch.Tensor
    rel_pose: torch.Tensor


@dataclass(frozen=True)
class TemporalLosses(LossTerms):
    """L_temp (Sec. 3.3): ``total = lambda_temp`` times the weighted sum of the four parts.

    Attributes:
        camera: camera-encoding part.
        mano: MANO-parameter part.
        mask: mask part.
        landmarks: 2D landmark part.

    """

    camera: torch.Tensor
    mano: torch.Tensor
    mask: torch.Tensor
    landmarks: torch.Tensor


def joint_loss(groups: Iterable[LossTerms]) -> torch.Tensor:
    """Return L_joint, the sum of the groups' ``total`` (Stage I: pass only its heads' groups).

    Raises:
        InputError: when ``groups`` is empty or holds something other than ``LossTerms``.

    """
    totals = []
    for group in groups:
        if not isinstance(group, LossTerms):
            raise InputError(f'joint_loss: expected LossTerms results of the loss functions, '
                             f'got {type(group).__name__}')
        totals.append(group.total)
    if not totals:
        raise InputError('joint_loss: got no loss groups; pass the results of at least one '
                         'loss function')
    return sum(totals[1:], start=totals[0])
