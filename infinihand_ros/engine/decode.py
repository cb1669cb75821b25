"""From one block of geometry-branch outputs to per-frame results with camera and world hands.

Per block: camera poses and intrinsics from the pose encodings (or the given intrinsics), hand
boxes from the mask head, one batched hand-branch pass over every box of the block, then frame by
frame, in order: the metric-scale estimate takes the frame's hands, the camera translation is
scaled, and the hands are moved to the world frame (paper eq. 9). Frame-by-frame order makes
the results independent of how frames were grouped into blocks.
"""

from dataclasses import dataclass
from dataclasses import replace

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.mano_frames import transform_mano_params
from infinihand_ros.engine.frame_input import Letterbox
from infinihand_ros.engine.metric_scale import MetricScaleEstimator
from infinihand_ros.model.geometry_model import GeometryOutput
from infinihand_ros.model.hand.hand_branch import HandBoxes
from infinihand_ros.model.hand.hand_branch import HandBranch
from infinihand_ros.model.heads.mask_head import masks_to_boxes
from infinihand_ros.model.pose_encoding import encoding_to_matrices
from infinihand_ros.model.pose_encoding import FOV_H
import numpy as np
import torch


@dataclass(frozen=True)
class PreparedFrame:
    """A checked frame waiting for the model.

    Attributes:
        index: 0-based index in the stream.
        timestamp_ns: the source image's stamp.
        pixels: (3, H, W) float32 RGB in [0, 1] at the model size (letterboxed).
        letterbox: mapping between source and model pixels.
        intrinsics: the given source intrinsics, or None (the model's FoV is used).
        keyframe: whether the frame enters the streaming memory.

    """

    index: int
    timestamp_ns: int
    pixels: torch.Tensor
    letterbox: Letterbox
    intrinsics: Intrinsics | None
    keyframe: bool


@dataclass(frozen=True)
class _BlockHands:
    """Hand-branch outputs of a block as numpy arrays, one row per detected hand."""

    frame: np.ndarray
    side: np.ndarray
    presence: np.ndarray
    box: np.ndarray
    global_orient: np.ndarray
    hand_pose: np.ndarray
    betas: np.ndarray
    transl: np.ndarray
    joints_cam: np.ndarray
    joints_2d: np.ndarray
    depth_ratio: np.ndarray


@dataclass(frozen=True)
class DecodeSettings:
    """Thresholds of decoding (from the model's mask config and the engine config)."""

    mask_threshold: float
    min_pixels: int
    presence_threshold: float
    fov_range_rad: tuple[float, float]


def _intrinsics_matrices(frames: list[PreparedFrame], predicted: torch.Tensor) -> torch.Tensor:
    """Return (S, 3, 3) model-size K: the given intrinsics where known, else the predicted."""
    matrices = predicted.clone()
    for row, frame in enumerate(frames):
        if frame.intrinsics is not None:
            given = frame.letterbox.intrinsics_to_model(frame.intrinsics).matrix()
            matrices[row] = torch.as_tensor(given, dtype=matrices.dtype)
    return matrices


def _detect_hands(output: GeometryOutput, frames: list[PreparedFrame], hand_branch: HandBranch,
                  intrinsics: torch.Tensor, settings: DecodeSettings) -> _BlockHands:
    """Run the hand branch on every hand the masks show in the block."""
    masks = output.hand_masks[0]  # (S, 2, H, W)
    presence = masks.amax(dim=(-2, -1))
    boxes, valid = masks_to_boxes(masks, settings.mask_threshold, settings.min_pixels,
                                  expand=1.0)  # tight: the hand branch expands them itself
    detected = valid & (presence > settings.presence_threshold)
    frame_index, side = torch.nonzero(detected, as_tuple=True)
    images = torch.stack([frame.pixels for frame in frames]).to(masks.device)
    out = hand_branch(images, output.patch_features[0], intrinsics.to(masks.device),
                      HandBoxes(boxes[frame_index, side], frame_index, side))
    depth_ratio = _hand_depth_ratios(output.depth[0], frame_index, out.joints_2d,
                                     out.joints_cam[..., 2])

    def numpy(tensor: torch.Tensor) -> np.ndarray:
        return tensor.detach().double().cpu().numpy()

    return _BlockHands(
        frame=frame_index.cpu().numpy(), side=side.cpu().numpy(),
        presence=numpy(presence[frame_index, side]), box=numpy(boxes[frame_index, side]),
        global_orient=numpy(out.mano_cam.global_orient), hand_pose=numpy(out.mano_cam.hand_pose),
        betas=numpy(out.mano_cam.betas), transl=numpy(out.mano_cam.transl),
        joints_cam=numpy(out.joints_cam),
        joints_2d=numpy(out.joints_2d), depth_ratio=numpy(depth_ratio))


def _hand_depth_ratios(depth: torch.Tensor, frame_index: torch.Tensor, joints_2d: torch.Tensor,
                       joints_depth: torch.Tensor) -> torch.Tensor:
    """Return per hand the median of metric joint depth / model depth at the joint's pixel.

    Joints outside the image or with non-positive depths are left out (NaN when none is left);
    the median over the 21 joints makes occluded joints and the limb radius matter little.

    Args:
        depth: (S, H, W) model depth maps of the block.
        frame_index: (N,) frame of each hand.
        joints_2d: (N, 21, 2) joint pixels (u, v).
        joints_depth: (N, 21) metric joint depths from the hand branch.

    """
    height, width = depth.shape[-2:]
    pixels = joints_2d.round().long()
    inside = ((pixels[..., 0] >= 0) & (pixels[..., 0] < width) & (pixels[..., 1] >= 0)
              & (pixels[..., 1] < height))
    columns = pixels[..., 0].clamp(0, width - 1)
    rows = pixels[..., 1].clamp(0, height - 1)
    model = depth[frame_index[:, None], rows, columns]
    valid = inside & (model > 0) & (joints_depth > 0) & torch.isfinite(model)
    ratios = torch.where(valid, joints_depth / model.clamp_min(1e-12),
                         torch.full_like(model, float('nan')))
    return ratios.nanmedian(dim=-1).values


def place_in_world(hand: HandState, pose: CameraPose) -> HandState:
    """Return ``hand`` with joints and MANO parameters in the world frame of ``pose`` (eq. 9)."""
    # MANO rotates about its rest root joint J0, and the posed wrist is J0 + transl in any frame.
    root = hand.joints_cam[0] - hand.mano_cam.transl
    return replace(hand, joints_world=pose.to_world(hand.joints_cam),
                   mano_world=transform_mano_params(hand.mano_cam, pose.rotation,
                                                    pose.translation, root))


def _hand_state(hands: _BlockHands, row: int, letterbox: Letterbox, pose: CameraPose
                ) -> HandState:
    """Build one hand's state in camera and world frames, pixels mapped to the source image."""
    mano_cam = ManoParams(hands.global_orient[row], hands.hand_pose[row], hands.betas[row],
                          hands.transl[row])
    box = letterbox.points_to_source(hands.box[row].reshape(2, 2)).reshape(4)
    return place_in_world(HandState(
        side=int(hands.side[row]), mano_cam=mano_cam, joints_cam=hands.joints_cam[row],
        joints_2d=letterbox.points_to_source(hands.joints_2d[row]), box_xyxy=box,
        confidence=float(np.clip(hands.presence[row], 0.0, 1.0))), pose)


def decode_block(output: GeometryOutput, frames: list[PreparedFrame], hand_branch: HandBranch,
                 scale: MetricScaleEstimator, settings: DecodeSettings) -> list[FrameResult]:
    """Turn a block's geometry outputs into one ``FrameResult`` per frame, in order."""
    height, width = output.depth.shape[-2:]
    with torch.inference_mode():
        encoding = output.pose_encoding[0].double().clone()
        encoding[:, FOV_H:] = encoding[:, FOV_H:].clamp(*settings.fov_range_rad)
        cam_to_world, predicted_k = encoding_to_matrices(encoding, height, width)
        intrinsics = _intrinsics_matrices(frames, predicted_k)
        hands = _detect_hands(output, frames, hand_branch, intrinsics.float(), settings)
    cam_to_world = cam_to_world.cpu().numpy()
    intrinsics = intrinsics.cpu().numpy()
    results = []
    for row, frame in enumerate(frames):
        rows = np.flatnonzero(hands.frame == row)
        scale.observe(hands.depth_ratio[rows], np.ones(len(rows)))
        metric = scale.estimate().scale
        transform = cam_to_world[row].copy()
        transform[:3, 3] *= metric
        pose = CameraPose.from_matrix(transform)
        source_intrinsics = frame.intrinsics or frame.letterbox.intrinsics_to_source(
            Intrinsics.from_matrix(intrinsics[row], width, height))
        depth = None
        if frame.keyframe:
            model_depth = output.depth[0, row].detach().float().cpu().numpy() * metric
            depth = frame.letterbox.map_to_source(model_depth).astype(np.float32)
        results.append(FrameResult(
            timestamp_ns=frame.timestamp_ns, frame_index=frame.index, camera_pose=pose,
            intrinsics=source_intrinsics,
            hands=tuple(_hand_state(hands, r, frame.letterbox, pose) for r in rows),
            is_keyframe=frame.keyframe, depth=depth, metric_scale=metric))
    return results
