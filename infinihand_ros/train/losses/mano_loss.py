"""Camera-space MANO loss L_MANO (paper Sec. 3.2 and appendix B.2).

Per valid hand (orientation, pose, shape, translation) or per valid joint (3D joints,
reprojection), then averaged over the valid set of the batch:

    L_orient   = d_SO(3)(R(Phi_hat^c), R(Phi^c))
    L_pose     = (1/15) sum_k d_SO(3)(R(Theta_hat_k), R(Theta_k))
    L_shape    = (1/10) ||beta_hat - beta||_2^2
    L_trans    = (1/3) ||t_hat^c - t^c||_2^2
    L_joints^c = (1/3) ||J_hat^c_j - J^c_j||_1
    L_reproj   = ||pi_K(J_hat^c_j) - p^img_j||_1

``L_MANO = lambda_g L_orient + lambda_theta L_pose + lambda_beta L_shape + lambda_t L_trans +
lambda_J L_joints^c + lambda_r L_reproj``. Axis-angle goes to matrices with roma (Rodrigues).
Interpretations: "normalised image coordinates" are grid_sample's ``align_corners=False`` ones
of the full image (``x_n = (2 u + 1) / W - 1``, the convention of the crop coordinates), and
the target is given in pixels and normalised here with the same image size, so projection and
target always share intrinsics and normalisation. Predicted depths are floored at
``mano.min_depth_m`` before dividing. Each part has its own valid set: the hand flag (or joint
flag) and finite targets for that part.
"""

from typing import Final

from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.model.hand.crop_camera import pixels_to_normalized
from infinihand_ros.train.losses.loss_config import LossConfig
from infinihand_ros.train.losses.primitives import check_like
from infinihand_ros.train.losses.primitives import check_mask
from infinihand_ros.train.losses.primitives import check_shape
from infinihand_ros.train.losses.primitives import finite_or_zero
from infinihand_ros.train.losses.primitives import finite_rows
from infinihand_ros.train.losses.primitives import masked_mean
from infinihand_ros.train.losses.primitives import promote
from infinihand_ros.train.losses.primitives import so3_distance
from infinihand_ros.train.losses.terms import ManoLosses
import roma
import torch

#: Terms whose valid set is per hand (``mano_valid``); the others are per joint.
_PER_HAND: Final = ('orient', 'pose', 'shape', 'trans')
#: The target each term's valid set checks for finiteness.
_TARGET_OF: Final = {'orient': 'global_orient', 'pose': 'hand_pose', 'shape': 'betas',
                     'trans': 'transl', 'joints': 'joints_cam', 'reproj': 'joints_2d'}


def project_normalized(points_cam: torch.Tensor, intrinsics: torch.Tensor,
                       image_size: tuple[int, int], min_depth_m: float) -> torch.Tensor:
    """Project camera-frame points into normalised image coordinates.

    Args:
        points_cam: (B, S, 2, 21, 3) points in the OpenCV camera frame, metres.
        intrinsics: (B, S, 3, 3) K in pixels of the image of size ``image_size``.
        image_size: (height, width) in pixels.
        min_depth_m: depths are floored at this before dividing.

    Returns:
        (B, S, 2, 21, 2) ``align_corners=False`` coordinates (-1, 1 at the outer pixel edges).

    """
    depth = points_cam[..., 2:].clamp(min=min_depth_m)
    rays = torch.cat((points_cam[..., :2] / depth, torch.ones_like(depth)), dim=-1)
    pixels = rays @ intrinsics[..., None, :, :].transpose(-1, -2)
    height, width = image_size
    return pixels_to_normalized(pixels[..., :2], width, height)


def _check_inputs(pred: dict[str, torch.Tensor], target: dict[str, torch.Tensor],
                  intrinsics: torch.Tensor, mano_valid: torch.Tensor,
                  joints_valid: torch.Tensor) -> None:
    """Raise InputError for shapes that do not follow ``mano_losses``' layout."""
    hands = tuple(pred['global_orient'].shape[:-1])
    expected = {'global_orient': (*hands, 3), 'hand_pose': (*hands, NUM_HAND_POSE_JOINTS, 3),
                'betas': (*hands, NUM_BETAS), 'transl': (*hands, 3),
                'joints_cam': (*hands, NUM_JOINTS, 3), 'joints_2d': (*hands, NUM_JOINTS, 2)}
    for key, shape in expected.items():
        if key in pred:
            check_shape(f'pred_{key}', pred[key], shape)
            check_like(f'target_{key}', target[key], f'pred_{key}', pred[key])
        else:
            check_shape(f'target_{key}', target[key], shape)
    check_shape('intrinsics', intrinsics, (*hands[:-1], 3, 3))
    check_mask('mano_valid', mano_valid, hands)
    check_mask('joints_valid', joints_valid, (*hands, NUM_JOINTS))


def mano_losses(*, pred_global_orient: torch.Tensor, pred_hand_pose: torch.Tensor,
                pred_betas: torch.Tensor, pred_transl: torch.Tensor,
                pred_joints_cam: torch.Tensor, target_global_orient: torch.Tensor,
                target_hand_pose: torch.Tensor, target_betas: torch.Tensor,
                target_transl: torch.Tensor, target_joints_cam: torch.Tensor,
                target_joints_2d: torch.Tensor, intrinsics: torch.Tensor,
                image_size: tuple[int, int], mano_valid: torch.Tensor,
                joints_valid: torch.Tensor, config: LossConfig) -> ManoLosses:
    """Return the six MANO terms and L_MANO.

    Args:
        pred_global_orient: (B, S, 2, 3) axis-angle Phi_hat^c in the image camera frame (rad),
            side axis [left, right]; B, S may be any leading dims.
        pred_hand_pose: (B, S, 2, 15, 3) axis-angle Theta_hat, MANO joint order.
        pred_betas: (B, S, 2, 10) shape.
        pred_transl: (B, S, 2, 3) MANO translation t_hat^c in the camera frame (m).
        pred_joints_cam: (B, S, 2, 21, 3) joints decoded from the predicted MANO, camera
            frame (m), OpenPose order.
        target_global_orient: (B, S, 2, 3) like the prediction.
        target_hand_pose: (B, S, 2, 15, 3).
        target_betas: (B, S, 2, 10).
        target_transl: (B, S, 2, 3), the same MANO translation convention as the prediction.
        target_joints_cam: (B, S, 2, 21, 3) camera-frame target joints (m).
        target_joints_2d: (B, S, 2, 21, 2) target joints in pixels of the image ``intrinsics``
            describes.
        intrinsics: (B, S, 3, 3) K of each frame (pixels), used for the prediction's projection.
        image_size: (height, width) in pixels of that image (the normalisation of both sides).
        mano_valid: (B, S, 2) bool, True where the hand's MANO annotation exists.
        joints_valid: (B, S, 2, 21) bool, True where the joint's 3D/2D annotation exists.
        config: the loss config (``config.mano``, ``config.rotation_clamp_eps``).

    Returns:
        ``ManoLosses``; each term is exactly 0 when its valid set is empty.

    Raises:
        InputError: for shapes that do not follow the layout above or non-bool masks.

    """
    pred = {'global_orient': pred_global_orient, 'hand_pose': pred_hand_pose,
            'betas': pred_betas, 'transl': pred_transl, 'joints_cam': pred_joints_cam}
    target = {'global_orient': target_global_orient, 'hand_pose': target_hand_pose,
              'betas': target_betas, 'transl': target_transl, 'joints_cam': target_joints_cam,
              'joints_2d': target_joints_2d}
    _check_inputs(pred, target, intrinsics, mano_valid, joints_valid)
    *values, intrinsics = promote(*pred.values(), *target.values(), intrinsics)
    count = len(pred)
    pred, target = dict(zip(pred, values[:count])), dict(zip(target, values[count:]))
    errors = _per_item_errors(pred, {key: finite_or_zero(value) for key, value in target.items()},
                              intrinsics, image_size, config)
    valid = {key: (mano_valid if key in _PER_HAND else joints_valid)
             & finite_rows(target[_TARGET_OF[key]], dims=2 if key == 'pose' else 1)
             for key in errors}
    terms = {key: masked_mean(errors[key], valid[key]) for key in errors}
    weights = config.mano
    total = (weights.orient_weight * terms['orient'] + weights.pose_weight * terms['pose']
             + weights.shape_weight * terms['shape'] + weights.trans_weight * terms['trans']
             + weights.joints_weight * terms['joints']
             + weights.reproj_weight * terms['reproj'])
    return ManoLosses(total=total, **terms)


def _per_item_errors(pred: dict[str, torch.Tensor], target: dict[str, torch.Tensor],
                     intrinsics: torch.Tensor, image_size: tuple[int, int],
                     config: LossConfig) -> dict[str, torch.Tensor]:
    """Return each term's error per hand (B, S, 2) or per joint (B, S, 2, 21), finite targets."""
    eps = config.rotation_clamp_eps
    projected = project_normalized(pred['joints_cam'], intrinsics, image_size,
                                   config.mano.min_depth_m)
    height, width = image_size
    target_2d = pixels_to_normalized(target['joints_2d'], width, height)
    return {
        'orient': so3_distance(roma.rotvec_to_rotmat(pred['global_orient']),
                               roma.rotvec_to_rotmat(target['global_orient']), eps),
        'pose': so3_distance(roma.rotvec_to_rotmat(pred['hand_pose']),
                             roma.rotvec_to_rotmat(target['hand_pose']), eps).mean(dim=-1),
        'shape': (pred['betas'] - target['betas']).square().mean(dim=-1),
        'trans': (pred['transl'] - target['transl']).square().mean(dim=-1),
        'joints': (pred['joints_cam'] - target['joints_cam']).abs().mean(dim=-1),
        'reproj': (projected - target_2d).abs().sum(dim=-1),
    }
