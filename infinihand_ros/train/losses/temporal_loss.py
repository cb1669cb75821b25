"""Temporal consistency L_temp (paper Sec. 3.3): camera, MANO, masks and 2D landmarks.

The paper names the four parts but gives no formula. Our choice, for every part: between two
consecutive frames t, t + 1 that are both in the part's valid set (annotations exist, as every
term of L_joint is "evaluated conditionally on annotation availability"), the predicted change
must match the annotated change, ``|(x_hat_{t+1} - x_hat_t) - (x_{t+1} - x_t)|``, i.e. the
prediction error must not jump between frames. Unlike a plain smoothness prior this leaves real
motion alone. Each part is averaged over its valid pairs (pooled over the batch):

- camera: (1/9) ||delta of the nine absolute-pose residuals||_1 (kappa-normalised anchored
  translation, sign-aligned quaternion, FoV; ``camera_loss.camera_residuals``).
- MANO, per hand: d_SO(3)(R_hat_t^T R_hat_{t+1}, R_t^T R_{t+1}) for the camera-frame orientation
  plus its mean over the 15 local joints, plus (1/10) ||delta beta error||_1 and (1/3) ||delta
  t^c error||_1 (unweighted sum; the L_MANO weights are not reused).
- masks, per hand: mean over pixels of |delta (sigmoid(logits) - M)|.
- 2D landmarks, per joint: ||delta (p_hat - p)||_1 in normalised crop coordinates.

``L_temp`` is their weighted sum and the group's total is ``lambda_temp L_temp``. Frame pairs
are neighbours in the clip's S axis; ``consecutive`` (B, S - 1) drops pairs that are not
adjacent in time (for instance anchors followed by a window that does not start right after).
"""

from infinihand_ros.core.errors import InputError
from infinihand_ros.train.losses.camera_loss import camera_residuals
from infinihand_ros.train.losses.camera_loss import camera_valid_set
from infinihand_ros.train.losses.camera_loss import check_camera_inputs
from infinihand_ros.train.losses.landmark_loss import landmark_valid_set
from infinihand_ros.train.losses.loss_config import LossConfig
from infinihand_ros.train.losses.mask_loss import mask_valid_set
from infinihand_ros.train.losses.primitives import check_like
from infinihand_ros.train.losses.primitives import check_mask
from infinihand_ros.train.losses.primitives import consecutive_pairs
from infinihand_ros.train.losses.primitives import finite_or_zero
from infinihand_ros.train.losses.primitives import finite_rows
from infinihand_ros.train.losses.primitives import masked_mean
from infinihand_ros.train.losses.primitives import promote
from infinihand_ros.train.losses.primitives import so3_distance
from infinihand_ros.train.losses.terms import TemporalLosses
import roma
import torch


def _delta(values: torch.Tensor) -> torch.Tensor:
    """Return ``x_{t+1} - x_t`` along the S axis (dim 1)."""
    return values[:, 1:] - values[:, :-1]


def _relative_angle(pred: torch.Tensor, target: torch.Tensor, clamp_eps: float) -> torch.Tensor:
    """Return d_SO(3) between predicted and target frame-to-frame rotations (axis-angle in)."""
    pred_r, target_r = roma.rotvec_to_rotmat(pred), roma.rotvec_to_rotmat(target)
    pred_step = pred_r[:, :-1].transpose(-1, -2) @ pred_r[:, 1:]
    target_step = target_r[:, :-1].transpose(-1, -2) @ target_r[:, 1:]
    return so3_distance(pred_step, target_step, clamp_eps)


def temporal_camera_loss(*, pred_pose_encoding: torch.Tensor, target_T_world_cam: torch.Tensor,
                         target_fov: torch.Tensor, camera_valid: torch.Tensor,
                         scale: torch.Tensor, consecutive: torch.Tensor | None = None
                         ) -> torch.Tensor:
    """Return the camera part of L_temp; inputs as ``camera_loss.camera_losses``.

    Args:
        pred_pose_encoding: (B, S, 9) predicted camera-to-world encodings.
        target_T_world_cam: (B, S, 4, 4) annotated camera-to-world poses.
        target_fov: (B, S, 2) annotated (fov_h, fov_w), radians.
        camera_valid: (B, S) bool camera annotations.
        scale: (B,) kappa.
        consecutive: (B, S - 1) bool, frame t + 1 follows frame t; None: all do.

    Raises:
        InputError: for shapes that do not follow the layout or non-bool masks.

    """
    check_camera_inputs(pred_pose_encoding, target_T_world_cam, target_fov, camera_valid, scale)
    pred_pose_encoding, target_T_world_cam, target_fov, scale = promote(
        pred_pose_encoding, target_T_world_cam, target_fov, scale)
    valid = camera_valid_set(target_T_world_cam, target_fov, camera_valid)
    residuals = camera_residuals(pred_pose_encoding, target_T_world_cam, target_fov, scale)
    return masked_mean(_delta(residuals).abs().mean(dim=-1), consecutive_pairs(valid, consecutive))


def temporal_mano_loss(*, pred_global_orient: torch.Tensor, pred_hand_pose: torch.Tensor,
                       pred_betas: torch.Tensor, pred_transl: torch.Tensor,
                       target_global_orient: torch.Tensor, target_hand_pose: torch.Tensor,
                       target_betas: torch.Tensor, target_transl: torch.Tensor,
                       mano_valid: torch.Tensor, config: LossConfig,
                       consecutive: torch.Tensor | None = None) -> torch.Tensor:
    """Return the MANO part of L_temp.

    Args:
        pred_global_orient: (B, S, 2, 3) camera-frame axis-angle (rad), side axis [left, right].
        pred_hand_pose: (B, S, 2, 15, 3) local axis-angle.
        pred_betas: (B, S, 2, 10).
        pred_transl: (B, S, 2, 3) camera-frame MANO translation (m).
        target_global_orient: (B, S, 2, 3).
        target_hand_pose: (B, S, 2, 15, 3).
        target_betas: (B, S, 2, 10).
        target_transl: (B, S, 2, 3).
        mano_valid: (B, S, 2) bool, the hand's MANO annotation exists.
        config: the loss config (``config.rotation_clamp_eps``).
        consecutive: (B, S - 1) bool, frame t + 1 follows frame t; None: all do.

    Raises:
        InputError: for mismatched shapes or non-bool masks.

    """
    pairs = {'global_orient': (pred_global_orient, target_global_orient),
             'hand_pose': (pred_hand_pose, target_hand_pose), 'betas': (pred_betas, target_betas),
             'transl': (pred_transl, target_transl)}
    for key, (pred, target) in pairs.items():
        check_like(f'target_{key}', target, f'pred_{key}', pred)
    check_mask('mano_valid', mano_valid, pred_global_orient.shape[:-1])
    orient, orient_t, pose, pose_t, betas, betas_t, transl, transl_t = promote(
        *(tensor for pair in pairs.values() for tensor in pair))
    valid = (mano_valid & finite_rows(orient_t) & finite_rows(pose_t, dims=2)
             & finite_rows(betas_t) & finite_rows(transl_t))
    eps = config.rotation_clamp_eps
    error = (_relative_angle(orient, finite_or_zero(orient_t), eps)
             + _relative_angle(pose, finite_or_zero(pose_t), eps).mean(dim=-1)
             + _delta(betas - finite_or_zero(betas_t)).abs().mean(dim=-1)
             + _delta(transl - finite_or_zero(transl_t)).abs().mean(dim=-1))
    return masked_mean(error, consecutive_pairs(valid, consecutive))


def temporal_mask_loss(*, logits: torch.Tensor, target: torch.Tensor, valid: torch.Tensor,
                       consecutive: torch.Tensor | None = None) -> torch.Tensor:
    """Return the mask part of L_temp; inputs (B, S, 2, H, W) as ``mask_loss.mask_losses``.

    Raises:
        InputError: for mismatched shapes or a non-bool ``valid``.

    """
    check_like('mask target', target, 'mask logits', logits)
    check_mask('mask valid', valid, logits.shape[:-2])
    logits, target = promote(logits, target)
    valid = mask_valid_set(target, valid)
    error = _delta(torch.sigmoid(logits) - finite_or_zero(target)).abs().mean(dim=(-2, -1))
    return masked_mean(error, consecutive_pairs(valid, consecutive))


def temporal_landmark_loss(*, pred: torch.Tensor, target: torch.Tensor, valid: torch.Tensor,
                           config: LossConfig, consecutive: torch.Tensor | None = None
                           ) -> torch.Tensor:
    """Return the 2D landmark part of L_temp; inputs (B, S, 2, 21, 2) as ``landmark_losses``.

    Raises:
        InputError: for mismatched shapes or a non-bool ``valid``.

    """
    check_like('landmark target', target, 'landmark pred', pred)
    check_mask('landmark valid', valid, pred.shape[:-1])
    pred, target = promote(pred, target)
    valid = landmark_valid_set(target, valid, config.landmarks.max_abs)
    error = _delta(pred - finite_or_zero(target)).abs().sum(dim=-1)
    return masked_mean(error, consecutive_pairs(valid, consecutive))


def temporal_losses(*, camera: torch.Tensor | None, mano: torch.Tensor | None,
                    mask: torch.Tensor | None, landmarks: torch.Tensor | None,
                    config: LossConfig) -> TemporalLosses:
    """Weight the four parts into ``lambda_temp L_temp``; a part passed as None counts as 0.

    Raises:
        InputError: when every part is None.

    """
    parts = {'camera': camera, 'mano': mano, 'mask': mask, 'landmarks': landmarks}
    given = [value for value in parts.values() if value is not None]
    if not given:
        raise InputError('temporal_losses: every part is None; pass at least one of camera, '
                         'mano, mask, landmarks')
    zero = torch.zeros((), dtype=given[0].dtype, device=given[0].device)
    parts = {key: zero if value is None else value for key, value in parts.items()}
    weights = config.temporal
    inner = (weights.camera_weight * parts['camera'] + weights.mano_weight * parts['mano']
             + weights.mask_weight * parts['mask']
             + weights.landmarks_weight * parts['landmarks'])
    return TemporalLosses(total=weights.weight * inner, **parts)
