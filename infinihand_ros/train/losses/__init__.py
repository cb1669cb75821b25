"""Training losses of InfiniHand, exactly as the paper's appendix B (and Sec. 3.2-3.3).

Every term is a pure function of plain tensors with documented shapes ``(B, S, ...)`` (batch,
clip frames; side axis [left, right]; OpenPose joint order) and boolean validity masks. Every term
averages over its valid set, pooled over the batch, and is exactly 0 (with finite zero
gradients) when that set is empty. Weights and constants come from ``LossConfig``
(``config/train_losses.yaml``). Group functions return ``LossTerms`` results whose ``total`` is
the group's weighted term of L_joint; ``joint_loss`` sums them.

Modules: ``loss_config`` (weights), ``primitives`` (masked mean, rho_eps, d_SO(3)), ``terms``
(result types, L_joint), ``mask_loss`` (L_mask), ``landmark_loss`` (L_2D), ``mano_loss``
(L_MANO), ``anchoring`` (anchor transform, kappa), ``world_joint_loss`` (L_joints^w),
``camera_loss`` (L_camera), ``temporal_loss`` (L_temp), ``depth_loss`` (L_depth, ours: the tiny
model's stand-in for pretrained depth).
"""

from infinihand_ros.train.losses.anchoring import anchor_points
from infinihand_ros.train.losses.anchoring import anchor_poses
from infinihand_ros.train.losses.anchoring import sample_scale
from infinihand_ros.train.losses.camera_loss import camera_losses
from infinihand_ros.train.losses.depth_loss import depth_losses
from infinihand_ros.train.losses.landmark_loss import landmark_losses
from infinihand_ros.train.losses.loss_config import CameraLossConfig
from infinihand_ros.train.losses.loss_config import DepthLossConfig
from infinihand_ros.train.losses.loss_config import LandmarkLossConfig
from infinihand_ros.train.losses.loss_config import load_loss_config
from infinihand_ros.train.losses.loss_config import LossConfig
from infinihand_ros.train.losses.loss_config import LOSSES_SECTION
from infinihand_ros.train.losses.loss_config import ManoLossConfig
from infinihand_ros.train.losses.loss_config import MaskLossConfig
from infinihand_ros.train.losses.loss_config import TemporalLossConfig
from infinihand_ros.train.losses.loss_config import WorldJointLossConfig
from infinihand_ros.train.losses.mano_loss import mano_losses
from infinihand_ros.train.losses.mask_loss import mask_losses
from infinihand_ros.train.losses.temporal_loss import temporal_camera_loss
from infinihand_ros.train.losses.temporal_loss import temporal_landmark_loss
from infinihand_ros.train.losses.temporal_loss import temporal_losses
from infinihand_ros.train.losses.temporal_loss import temporal_mano_loss
from infinihand_ros.train.losses.temporal_loss import temporal_mask_loss
from infinihand_ros.train.losses.terms import CameraLosses
from infinihand_ros.train.losses.terms import DepthLosses
from infinihand_ros.train.losses.terms import joint_loss
from infinihand_ros.train.losses.terms import LandmarkLosses
from infinihand_ros.train.losses.terms import LossTerms
from infinihand_ros.train.losses.terms import ManoLosses
from infinihand_ros.train.losses.terms import MaskLosses
from infinihand_ros.train.losses.terms import TemporalLosses
from infinihand_ros.train.losses.terms import WorldJointLosses
from infinihand_ros.train.losses.world_joint_loss import world_joint_losses

__all__ = [
    'CameraLossConfig', 'CameraLosses', 'DepthLossConfig', 'DepthLosses', 'LOSSES_SECTION',
    'LandmarkLossConfig', 'LandmarkLosses', 'LossConfig', 'LossTerms', 'ManoLossConfig',
    'ManoLosses', 'MaskLossConfig', 'MaskLosses', 'TemporalLossConfig', 'TemporalLosses',
    'WorldJointLossConfig', 'WorldJointLosses', 'anchor_points', 'anchor_poses',
    'camera_losses', 'depth_losses', 'joint_loss', 'landmark_losses', 'load_loss_config',
    'mano_losses', 'mask_losses', 'sample_scale', 'temporal_camera_loss',
    'temporal_landmark_loss', 'temporal_losses', 'temporal_mano_loss', 'temporal_mask_loss',
    'world_joint_losses',
]
