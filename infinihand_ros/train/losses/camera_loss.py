"""Camera loss L_camera = alpha_abs L_abs-pose + alpha_rel L_rel-pose (paper appendix B.3).

Absolute pose, over the valid frames V_cam:

    L_abs-pose = 1/(9 |V_cam|) sum_t [rho(u~_hat_t - u~_t) + rho(q_hat_t - q*_t)
                                      + rho(f_hat_t - f_t)]

with rho_eps per coordinate, summed; u~ the anchored translation divided by kappa, q* the target
quaternion with the sign of the prediction (q* = q if <q_hat, q> >= 0, else -q) and f = (fov_h,
fov_w). Relative pose, over ordered pairs (i, j), i != j, of valid frames in the pose-reference
window, with C_{j<-i} = C_j^-1 C_i (so dR_ji = R_j^T R_i, du_ji = R_j^T (u_i - u_j), translations
already divided by kappa):

    L_rel-pose = (1/N_pair) sum_{i != j} m_i m_j [d_SO(3)(dR_hat_ji, dR_ji)
                                                  + lambda_rel,u ||du_hat_ji - du_ji||_1]

Interpretations: the prediction is the camera head's 9-number encoding ``[t, q_xyzw, fov_h,
fov_w]`` of camera-to-world poses (our checkpoints' ``pose_direction``), already in the first
anchor frame, so it is not re-anchored; q_hat is compared raw (not normalised, as VGGT's camera
loss does) in the absolute term and normalised to a rotation in the relative term. A frame is in
V_cam when its camera annotation is flagged valid and finite and the clip's anchor (frame 0) is
too; the relative term needs no anchor (it is anchor-invariant). ``pose_window`` marks the
frames of W_pose; by default every frame of the clip (LingBot-Map's pose-reference window holds
64 frames, more than the paper's 4 + 16 x 2 clips).
"""

from typing import Final

from infinihand_ros.model.pose_encoding import FOV_H
from infinihand_ros.model.pose_encoding import POSE_ENCODING_SIZE
from infinihand_ros.model.pose_encoding import QUATERNION_XYZW
from infinihand_ros.model.pose_encoding import TRANSLATION
from infinihand_ros.train.losses.anchoring import anchor_poses
from infinihand_ros.train.losses.anchoring import anchor_valid
from infinihand_ros.train.losses.loss_config import LossConfig
from infinihand_ros.train.losses.primitives import check_mask
from infinihand_ros.train.losses.primitives import check_shape
from infinihand_ros.train.losses.primitives import finite_or_zero
from infinihand_ros.train.losses.primitives import finite_rows
from infinihand_ros.train.losses.primitives import masked_mean
from infinihand_ros.train.losses.primitives import promote
from infinihand_ros.train.losses.primitives import smooth_l1
from infinihand_ros.train.losses.primitives import so3_distance
from infinihand_ros.train.losses.terms import CameraLosses
import roma
import torch
import torch.nn.functional as F

#: Number of field-of-view entries (fov_h, fov_w) at the end of the encoding.
NUM_FOV: Final = POSE_ENCODING_SIZE - FOV_H


def check_camera_inputs(pred_pose_encoding: torch.Tensor, target_T_world_cam: torch.Tensor,
                        target_fov: torch.Tensor, camera_valid: torch.Tensor,
                        scale: torch.Tensor) -> None:
    """Raise InputError unless the camera inputs follow ``camera_losses``' layout."""
    check_shape('pred_pose_encoding', pred_pose_encoding, (None, None, POSE_ENCODING_SIZE))
    batch, frames = pred_pose_encoding.shape[:2]
    check_shape('target_T_world_cam', target_T_world_cam, (batch, frames, 4, 4))
    check_shape('target_fov', target_fov, (batch, frames, NUM_FOV))
    check_mask('camera_valid', camera_valid, (batch, frames))
    check_shape('scale', scale, (batch,))


def camera_valid_set(target_T_world_cam: torch.Tensor, target_fov: torch.Tensor,
                     camera_valid: torch.Tensor) -> torch.Tensor:
    """Return V_cam (B, S): flagged valid, finite pose and FoV, and the clip's anchor valid."""
    return (camera_valid & finite_rows(target_T_world_cam, dims=2) & finite_rows(target_fov)
            & anchor_valid(camera_valid, target_T_world_cam)[:, None])


def camera_residuals(pred_pose_encoding: torch.Tensor, target_T_world_cam: torch.Tensor,
                     target_fov: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """Return the (B, S, 9) residuals [u~_hat - u~, q_hat - q*, f_hat - f] of the absolute term.

    Args:
        pred_pose_encoding: (B, S, 9) predicted encodings (see the module docstring).
        target_T_world_cam: (B, S, 4, 4) annotated camera-to-world poses (dataset world).
        target_fov: (B, S, 2) annotated (fov_h, fov_w) in radians.
        scale: (B,) kappa.

    Returns:
        Residuals, finite wherever the prediction is (invalid targets are read as zeros).

    """
    with torch.no_grad():
        anchored = anchor_poses(target_T_world_cam)
        quaternion = finite_or_zero(roma.rotmat_to_unitquat(anchored[..., :3, :3]))
    kappa = scale[:, None, None]
    pred_quaternion = pred_pose_encoding[..., QUATERNION_XYZW]
    aligned = (pred_quaternion * quaternion).sum(dim=-1, keepdim=True) >= 0
    return torch.cat((
        pred_pose_encoding[..., TRANSLATION] / kappa - anchored[..., :3, 3] / kappa,
        pred_quaternion - torch.where(aligned, quaternion, -quaternion),
        pred_pose_encoding[..., FOV_H:] - finite_or_zero(target_fov)), dim=-1)


def relative_pose_errors(pred_pose_encoding: torch.Tensor, target_T_world_cam: torch.Tensor,
                         scale: torch.Tensor, config: LossConfig) -> torch.Tensor:
    """Return the (B, S, S) per-pair errors [j, i] of L_rel-pose (diagonal included)."""
    rotation = roma.unitquat_to_rotmat(F.normalize(pred_pose_encoding[..., QUATERNION_XYZW],
                                                   dim=-1))
    translation = pred_pose_encoding[..., TRANSLATION] / scale[:, None, None]
    target = finite_or_zero(target_T_world_cam)
    pred_rel_r, pred_rel_u = _relative_motion(rotation, translation)
    target_rel_r, target_rel_u = _relative_motion(target[..., :3, :3],
                                                  target[..., :3, 3] / scale[:, None, None])
    angle = so3_distance(pred_rel_r, target_rel_r, config.rotation_clamp_eps)
    shift = (pred_rel_u - target_rel_u).abs().sum(dim=-1)
    return angle + config.camera.rel_translation_weight * shift


def _relative_motion(rotation: torch.Tensor, translation: torch.Tensor
                     ) -> tuple[torch.Tensor, torch.Tensor]:
    """Return C_j^-1 C_i as rotations (B, S, S, 3, 3) and translations (B, S, S, 3), [j, i]."""
    rotation_t = rotation.transpose(-1, -2)
    relative_r = rotation_t[:, :, None] @ rotation[:, None, :]
    offset = translation[:, None, :] - translation[:, :, None]
    relative_u = (rotation_t[:, :, None] @ offset[..., None])[..., 0]
    return relative_r, relative_u


def camera_losses(*, pred_pose_encoding: torch.Tensor, target_T_world_cam: torch.Tensor,
                  target_fov: torch.Tensor, camera_valid: torch.Tensor, scale: torch.Tensor,
                  config: LossConfig, pose_window: torch.Tensor | None = None) -> CameraLosses:
    """Return L_abs-pose, L_rel-pose and lambda_cam L_camera.

    Args:
        pred_pose_encoding: (B, S, 9) the camera head's (activated) encodings
            ``[t(3), q_xyzw(4), fov_h, fov_w]`` of camera-to-world poses, world = first anchor
            camera, FoV in radians.
        target_T_world_cam: (B, S, 4, 4) annotated camera-to-world poses (dataset world frame;
            frame 0 is the anchor), metres.
        target_fov: (B, S, 2) annotated (fov_h, fov_w) in radians (e.g. from
            ``pose_encoding.cam_to_world_to_encoding``).
        camera_valid: (B, S) bool m^cam, the frame's camera annotation exists.
        scale: (B,) kappa per sample (``anchoring.sample_scale``), > 0.
        config: the loss config (``config.camera``, ``config.rotation_clamp_eps``).
        pose_window: (B, S) bool, frames in the pose-reference window W_pose; None: all.

    Returns:
        ``CameraLosses``; each term is exactly 0 when its valid set (frames, or ordered pairs of
        distinct frames) is empty.

    Raises:
        InputError: for shapes that do not follow the layout above or non-bool masks.

    """
    check_camera_inputs(pred_pose_encoding, target_T_world_cam, target_fov, camera_valid, scale)
    pred_pose_encoding, target_T_world_cam, target_fov, scale = promote(
        pred_pose_encoding, target_T_world_cam, target_fov, scale)
    valid = camera_valid_set(target_T_world_cam, target_fov, camera_valid)
    residuals = camera_residuals(pred_pose_encoding, target_T_world_cam, target_fov, scale)
    abs_error = smooth_l1(residuals, config.camera.epsilon)
    abs_pose = masked_mean(abs_error, valid[..., None].expand_as(abs_error))
    in_window = camera_valid & finite_rows(target_T_world_cam, dims=2)
    if pose_window is not None:
        check_mask('pose_window', pose_window, camera_valid.shape)
        in_window = in_window & pose_window
    frames = camera_valid.shape[1]
    distinct = ~torch.eye(frames, dtype=torch.bool, device=camera_valid.device)
    pairs = in_window[:, :, None] & in_window[:, None, :] & distinct
    rel_pose = masked_mean(
        relative_pose_errors(pred_pose_encoding, target_T_world_cam, scale, config), pairs)
    weights = config.camera
    total = weights.weight * (weights.abs_weight * abs_pose + weights.rel_weight * rel_pose)
    return CameraLosses(total=total, abs_pose=abs_pose, rel_pose=rel_pose)
