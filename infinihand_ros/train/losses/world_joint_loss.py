"""World-space joint loss L_joints^w (paper Sec. 3.3 and appendix B.3).

    L_joints^w = (1/N_J) sum_{t,s,j} m^J_{t,s} rho_eps(J~_hat^{w,s}_{t,j} - J~^{w,s}_{t,j})

with rho_eps applied per coordinate and summed, and N_J the number of valid joint coordinates
(so: the mean of rho_eps over valid coordinates, pooled over the batch). The prediction is
``J_hat^w = R_hat_t J_hat^c + u_hat_t`` (the anchor transformation, eq. camera_to_world, with the
predicted camera-to-world poses, whose world is the first anchor camera); the target is the
dataset's joint annotation (not joints decoded from ground-truth MANO) moved into the
first-anchor frame (``anchoring.py``). Both are divided by the sample's kappa. m^J is the hand
flag; a coordinate also leaves the valid set when its target is not finite or the clip has no
anchor camera annotation.
"""

from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.train.losses.anchoring import anchor_points
from infinihand_ros.train.losses.anchoring import anchor_valid
from infinihand_ros.train.losses.anchoring import camera_to_world
from infinihand_ros.train.losses.loss_config import LossConfig
from infinihand_ros.train.losses.primitives import check_like
from infinihand_ros.train.losses.primitives import check_mask
from infinihand_ros.train.losses.primitives import check_shape
from infinihand_ros.train.losses.primitives import masked_mean
from infinihand_ros.train.losses.primitives import promote
from infinihand_ros.train.losses.primitives import smooth_l1
from infinihand_ros.train.losses.terms import WorldJointLosses
import torch


def world_joint_losses(*, pred_joints_cam: torch.Tensor, pred_T_world_cam: torch.Tensor,
                       target_joints_world: torch.Tensor, target_T_world_cam: torch.Tensor,
                       hand_valid: torch.Tensor, camera_valid: torch.Tensor,
                       scale: torch.Tensor, config: LossConfig) -> WorldJointLosses:
    """Return L_joints^w.

    Args:
        pred_joints_cam: (B, S, 2, 21, 3) predicted camera-frame joints (m), OpenPose order,
            side axis [left, right].
        pred_T_world_cam: (B, S, 4, 4) predicted camera-to-world poses, world = first anchor
            camera (decode the camera head with ``pose_encoding.encoding_to_cam_to_world``).
        target_joints_world: (B, S, 2, 21, 3) annotated world joints, dataset world frame (m).
        target_T_world_cam: (B, S, 4, 4) annotated camera-to-world poses, same world (frame 0
            is the anchor).
        hand_valid: (B, S, 2) bool m^J, the hand's joint annotation exists.
        camera_valid: (B, S) bool camera annotations (only frame 0, the anchor, matters here).
        scale: (B,) kappa per sample (``anchoring.sample_scale``), > 0.
        config: the loss config (``config.world_joints``).

    Returns:
        ``WorldJointLosses`` with ``total = lambda_w joints``; exactly 0 with no valid coordinate.

    Raises:
        InputError: for shapes that do not follow the layout above or non-bool masks.

    """
    check_shape('pred_joints_cam', pred_joints_cam, (None, None, 2, NUM_JOINTS, 3))
    batch, frames = pred_joints_cam.shape[:2]
    check_like('target_joints_world', target_joints_world, 'pred_joints_cam', pred_joints_cam)
    check_shape('pred_T_world_cam', pred_T_world_cam, (batch, frames, 4, 4))
    check_like('target_T_world_cam', target_T_world_cam, 'pred_T_world_cam', pred_T_world_cam)
    check_mask('hand_valid', hand_valid, (batch, frames, 2))
    check_mask('camera_valid', camera_valid, (batch, frames))
    check_shape('scale', scale, (batch,))
    pred_joints_cam, pred_T_world_cam, target_joints_world, target_T_world_cam, scale = promote(
        pred_joints_cam, pred_T_world_cam, target_joints_world, target_T_world_cam, scale)
    kappa = scale.reshape(batch, 1, 1, 1, 1)
    pred = camera_to_world(pred_joints_cam, pred_T_world_cam) / kappa
    target = anchor_points(target_joints_world, target_T_world_cam) / kappa
    valid = (hand_valid[..., None, None] & torch.isfinite(target_joints_world)
             & anchor_valid(camera_valid, target_T_world_cam).reshape(batch, 1, 1, 1, 1))
    joints = masked_mean(smooth_l1(pred - target, config.world_joints.epsilon), valid)
    return WorldJointLosses(total=config.world_joints.weight * joints, joints=joints)
