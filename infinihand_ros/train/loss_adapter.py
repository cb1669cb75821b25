"""From the model's per-clip predictions and a batch of targets to the loss groups of L_joint.

The hand branch returns one row per hand box (N boxes over the B x S frames); the losses take
dense ``(B, S, 2, ...)`` tensors with a side axis. ``scatter_hands`` places each box's outputs
at its (frame, side), zeros elsewhere, and the validity masks say which places hold a box
(``ran``) whose hand is annotated. The 2D landmark targets depend on the crop the box gave, so
they are made here per step: the annotated camera-frame joints projected through each box's
crop camera into canonical (left hands mirrored) normalised crop coordinates, the landmark
head's convention. The mask loss takes logits; the model returns probabilities, so
``logit(clamp(p, eps, 1 - eps))`` stands in (exact inside the clamp).
"""

from dataclasses import dataclass

from infinihand_ros.model.hand.crop_camera import CropCameras
from infinihand_ros.model.hand.crop_camera import flip_normalized
from infinihand_ros.model.hand.crop_camera import pixels_to_normalized
from infinihand_ros.train import sequence_reader as keys
from infinihand_ros.train.losses import camera_losses
from infinihand_ros.train.losses import depth_losses
from infinihand_ros.train.losses import joint_loss
from infinihand_ros.train.losses import landmark_losses
from infinihand_ros.train.losses import LossConfig
from infinihand_ros.train.losses import LossTerms
from infinihand_ros.train.losses import mano_losses
from infinihand_ros.train.losses import mask_losses
from infinihand_ros.train.losses import sample_scale
from infinihand_ros.train.losses import temporal_camera_loss
from infinihand_ros.train.losses import temporal_landmark_loss
from infinihand_ros.train.losses import temporal_losses
from infinihand_ros.train.losses import temporal_mano_loss
from infinihand_ros.train.losses import temporal_mask_loss
from infinihand_ros.train.losses import world_joint_losses
import torch

#: Crop-camera depths below this (m) give no landmark target (the joint is behind the crop).
_MIN_CROP_DEPTH_M = 1e-3


@dataclass(frozen=True)
class ClipPredictions:
    """Dense predictions of a batch of clips, side axis [left, right].

    Attributes:
        pose_encoding: (B, S, 9) camera encodings (activated).
        T_world_cam: (B, S, 4, 4) float64 predicted camera-to-world, first anchor world.
        intrinsics: (B, S, 3, 3) float64 K the hand branch ran with.
        mask_probabilities: (B, S, 2, H, W) hand probabilities.
        ran: (B, S, 2) bool, the hand branch ran on a box of that hand.
        global_orient: (B, S, 2, 3) camera-frame MANO orientation (axis-angle).
        hand_pose: (B, S, 2, 15, 3).
        betas: (B, S, 2, 10).
        transl: (B, S, 2, 3) camera-frame MANO translation (m).
        joints_cam: (B, S, 2, 21, 3) camera-frame joints (m).
        landmarks: (B, S, 2, 21, 2) canonical normalised crop landmarks.
        landmark_targets: (B, S, 2, 21, 2) the annotated joints in the same crops (no grad).
        depth: (B, S, H, W) predicted depth.
        depth_confidence: (B, S, H, W) its confidence (>= 1).

    """

    pose_encoding: torch.Tensor
    T_world_cam: torch.Tensor
    intrinsics: torch.Tensor
    mask_probabilities: torch.Tensor
    ran: torch.Tensor
    global_orient: torch.Tensor
    hand_pose: torch.Tensor
    betas: torch.Tensor
    transl: torch.Tensor
    joints_cam: torch.Tensor
    landmarks: torch.Tensor
    landmark_targets: torch.Tensor
    depth: torch.Tensor
    depth_confidence: torch.Tensor


def scatter_hands(values: torch.Tensor, frame: torch.Tensor, side: torch.Tensor,
                  frames: int) -> torch.Tensor:
    """Return (frames, 2, ...) holding row i of ``values`` (N, ...) at (frame[i], side[i]).

    Places without a row are zero; the gradient flows to ``values``.
    """
    dense = values.new_zeros((frames, 2, *values.shape[1:]))
    return dense.index_put((frame, side), values)


@torch.no_grad()
def crop_landmark_targets(joints_cam: torch.Tensor, cameras: CropCameras) -> torch.Tensor:
    """Project target joints into each box's canonical crop (normalised coordinates).

    Args:
        joints_cam: (N, 21, 3) annotated camera-frame joints (m), OpenPose order.
        cameras: the N boxes' crop cameras (``HandBranchOutput.cameras``).

    Returns:
        (N, 21, 2) ``align_corners=False`` coordinates of the canonical crop (left hands
        mirrored), NaN for joints behind the crop camera or without an annotation.

    """
    rotation = cameras.rotation_h_from_c.to(joints_cam.dtype)
    points = joints_cam @ rotation.transpose(-1, -2)  # X_h = R_h<-c X_c
    depth = points[..., 2:]
    rays = points / depth.clamp(min=_MIN_CROP_DEPTH_M)
    pixels = (rays @ cameras.intrinsics.to(joints_cam.dtype).transpose(-1, -2))[..., :2]
    size = cameras.crop_size
    normalized = flip_normalized(pixels_to_normalized(pixels, size, size), cameras.flipped)
    return torch.where(depth > _MIN_CROP_DEPTH_M, normalized,
                       torch.full_like(normalized, float('nan')))


def mask_logits(probabilities: torch.Tensor, eps: float) -> torch.Tensor:
    """Return the logits of hand probabilities clamped to [eps, 1 - eps] (float32 at least)."""
    probabilities = probabilities.float() if probabilities.dtype != torch.float64 \
        else probabilities
    return torch.logit(probabilities.clamp(eps, 1.0 - eps))


def _mano_args(pred: ClipPredictions, batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Return the predicted and target MANO parameters as keyword arguments."""
    args = {}
    for name in ('global_orient', 'hand_pose', 'betas', 'transl'):
        args[f'pred_{name}'] = getattr(pred, name)
        args[f'target_{name}'] = batch[f'mano_{name}']
    return args


def compute_loss_groups(pred: ClipPredictions, batch: dict[str, torch.Tensor],
                        groups: tuple[str, ...], config: LossConfig, mask_logit_eps: float,
                        frame_stride: int) -> dict[str, LossTerms]:
    """Return the requested loss groups of a batch of clips.

    Args:
        pred: the clips' dense predictions.
        batch: the batch (``sequence_reader`` keys, on the predictions' device).
        groups: names among ``train_config.LOSS_GROUPS``.
        config: loss weights.
        mask_logit_eps: clamp of the probabilities before ``logit``.
        frame_stride: sequence frames between clip frames (consecutive-pair test).

    Returns:
        ``{group name: LossTerms}`` in the order of ``groups``.

    """
    present = batch[keys.HAND_PRESENT]
    hands = pred.ran & present
    joints_valid = hands[..., None].expand(*hands.shape, pred.joints_cam.shape[-2])
    logits = mask_logits(pred.mask_probabilities, mask_logit_eps)
    target_masks = batch[keys.MASKS].float() / 255.0
    frames = batch[keys.FRAME_INDEX]
    consecutive = (frames[:, 1:] - frames[:, :-1]) == frame_stride
    camera_valid = batch[keys.CAMERA_VALID]
    scale = sample_scale(batch[keys.JOINTS_WORLD], present, batch[keys.T_WORLD_CAM],
                         camera_valid, config.min_scale_m)
    height, width = target_masks.shape[-2:]
    camera_args = {'pred_pose_encoding': pred.pose_encoding,
                   'target_T_world_cam': batch[keys.T_WORLD_CAM], 'target_fov': batch[keys.FOV],
                   'camera_valid': camera_valid, 'scale': scale}
    builders = {
        'mask': lambda: mask_losses(logits, target_masks, batch[keys.MASK_VALID], config=config),
        'landmarks': lambda: landmark_losses(pred.landmarks, pred.landmark_targets,
                                             joints_valid, config=config),
        'mano': lambda: mano_losses(
            **_mano_args(pred, batch), pred_joints_cam=pred.joints_cam,
            target_joints_cam=batch[keys.JOINTS_CAM], target_joints_2d=batch[keys.JOINTS_2D],
            intrinsics=pred.intrinsics, image_size=(height, width), mano_valid=hands,
            joints_valid=joints_valid, config=config),
        'world_joints': lambda: world_joint_losses(
            pred_joints_cam=pred.joints_cam, pred_T_world_cam=pred.T_world_cam,
            target_joints_world=batch[keys.JOINTS_WORLD],
            target_T_world_cam=batch[keys.T_WORLD_CAM], hand_valid=hands,
            camera_valid=camera_valid, scale=scale, config=config),
        'camera': lambda: camera_losses(**camera_args, config=config),
        'depth': lambda: depth_losses(pred.depth, pred.depth_confidence, batch[keys.DEPTH],
                                      scale, config=config),
        'temporal': lambda: temporal_losses(
            camera=temporal_camera_loss(**camera_args, consecutive=consecutive),
            mano=temporal_mano_loss(**_mano_args(pred, batch), mano_valid=hands,
                                    config=config, consecutive=consecutive),
            mask=temporal_mask_loss(logits=logits, target=target_masks,
                                    valid=batch[keys.MASK_VALID], consecutive=consecutive),
            landmarks=temporal_landmark_loss(pred=pred.landmarks,
                                             target=pred.landmark_targets,
                                             valid=joints_valid, config=config,
                                             consecutive=consecutive),
            config=config),
    }
    return {name: builders[name]() for name in groups}


def total_and_terms(groups: dict[str, LossTerms]) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Return L_joint and every term by dotted name (``mask.bce``, ``mask.total``, ...)."""
    terms = {}
    for name, group in groups.items():
        terms.update(group.named_terms(f'{name}.'))
    return joint_loss(groups.values()), terms
