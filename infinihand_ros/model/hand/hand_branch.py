"""The hand branch (paper Sec. 3.2): hand boxes in, camera-frame MANO hands out.

Per box: perspective crop through a virtual crop camera (left hands mirrored into right-hand
form), appearance ViT on the RGB crop (A), geometric adapter on the backbone patch features (G),
``Z = Conv1x1([G; A])``, MANO head and 2D landmark head, then decoding: un-flip left hands, run
the hand model translation-free, solve the lateral translation by least-squares projection with
the predicted depth fixed (eq. 5), and move orientation and translation to the camera frame
(eq. 6). The world frame (eq. 9) is the caller's step (``frames.camera_to_world``), with the
camera poses it trusts most. Everything is batched over boxes.
"""

from dataclasses import dataclass

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import MIN_PROJECTION_DEPTH_M
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.mano.base import HandModel
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.mano.mirror import mirror_axis_angle
from infinihand_ros.model.hand.adapter import GeometricAdapter
from infinihand_ros.model.hand.appearance_vit import AppearanceViT
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.hand.crop_camera import build_crop_cameras
from infinihand_ros.model.hand.crop_camera import CropCameras
from infinihand_ros.model.hand.crop_camera import flip_normalized
from infinihand_ros.model.hand.crop_camera import normalized_to_pixels
from infinihand_ros.model.hand.crop_camera import warp_to_crop
from infinihand_ros.model.hand.frames import hand_to_camera
from infinihand_ros.model.hand.landmark_head import LandmarkHead
from infinihand_ros.model.hand.lsp import solve_lateral_translation
from infinihand_ros.model.hand.mano_head import ManoHead
from infinihand_ros.model.hand.mano_head import ManoPrediction
import torch
from torch import nn


@dataclass(frozen=True)
class HandBoxes:
    """N hand boxes over a batch of B images.

    Attributes:
        boxes_xyxy: (N, 4) tight boxes (x0, y0, x1, y1) in input-image pixels, x1/y1 exclusive.
        batch_index: (N,) long, the image of each box.
        sides: (N,) long, 0 left, 1 right.

    """

    boxes_xyxy: torch.Tensor
    batch_index: torch.Tensor
    sides: torch.Tensor

    def __post_init__(self) -> None:
        """Check shapes and side values (InputError)."""
        n = self.boxes_xyxy.shape[0]
        if self.boxes_xyxy.shape != (n, 4) or self.batch_index.shape != (n,) or \
                self.sides.shape != (n,):
            raise InputError(f'hand boxes: expected boxes_xyxy (N, 4), batch_index (N,) and '
                             f'sides (N,), got {tuple(self.boxes_xyxy.shape)}, '
                             f'{tuple(self.batch_index.shape)}, {tuple(self.sides.shape)}')
        if ((self.sides != LEFT) & (self.sides != RIGHT)).any():
            raise InputError(f'hand boxes: sides must be 0 (left) or 1 (right), got '
                             f'{self.sides.unique().tolist()}')


@dataclass(frozen=True)
class ManoTensors:
    """MANO parameters of N hands in one frame.

    Attributes:
        global_orient: (N, 3) axis-angle, radians.
        hand_pose: (N, 15, 3) axis-angle per joint, relative to the flat hand.
        betas: (N, 10) shape.
        transl: (N, 3) translation, metres.

    """

    global_orient: torch.Tensor
    hand_pose: torch.Tensor
    betas: torch.Tensor
    transl: torch.Tensor


@dataclass(frozen=True)
class HandBranchOutput:
    """Per-box results of the hand branch (N boxes, in the order given).

    Attributes:
        cameras: the crop cameras (``R_h<-c``, ``K^h``, flips).
        mano_crop: MANO parameters in the crop-camera frame h (left hands un-flipped).
        mano_cam: MANO parameters in the image camera frame (eq. 6).
        root_joint: (N, 3) rest root joint ``J0(betas)`` (zero for the built-in hand), needed to
            move ``mano_cam`` to the world frame with ``frames.camera_to_world``.
        joints_cam: (N, 21, 3) joints in the camera frame, metres, OpenPose order.
        joints_2d: (N, 21, 2) joints projected into the input image, pixels.
        landmarks_crop: (N, 21, 2) the 2D head's landmarks, normalised canonical crop coordinates.
        log_depth: (N,) predicted ``l_z`` (wrist depth ``exp(l_z)`` in the crop frame, metres).
        confidence: (N,) per-box score in [0, 1].

    """

    cameras: CropCameras
    mano_crop: ManoTensors
    mano_cam: ManoTensors
    root_joint: torch.Tensor
    joints_cam: torch.Tensor
    joints_2d: torch.Tensor
    landmarks_crop: torch.Tensor
    log_depth: torch.Tensor
    confidence: torch.Tensor


def _check_inputs(images: torch.Tensor, features: torch.Tensor, intrinsics: torch.Tensor,
                  boxes: HandBoxes, feature_dim: int) -> None:
    """Raise InputError for inconsistent image, feature, intrinsics or box inputs."""
    if images.ndim != 4 or images.shape[1] != 3:
        raise InputError(f'hand branch images: expected (B, 3, H, W), got {tuple(images.shape)}')
    batch, _, height, width = images.shape
    if features.ndim != 4 or features.shape[:2] != (batch, feature_dim):
        raise InputError(f'hand branch features: expected (B={batch}, C={feature_dim}, Hp, Wp), '
                         f'got {tuple(features.shape)}')
    grid_h, grid_w = features.shape[-2:]
    if height % grid_h or width % grid_w or height // grid_h != width // grid_w:
        raise InputError(f'hand branch features: the {grid_h}x{grid_w} patch grid does not tile '
                         f'the {height}x{width} image with square patches; pass the features of '
                         'this image')
    if intrinsics.shape != (batch, 3, 3):
        raise InputError(f'hand branch intrinsics: expected (B={batch}, 3, 3), '
                         f'got {tuple(intrinsics.shape)}')
    if boxes.batch_index.numel() and (boxes.batch_index.min() < 0
                                      or boxes.batch_index.max() >= batch):
        raise InputError(f'hand boxes: batch_index must lie in [0, {batch}), got '
                         f'{boxes.batch_index.min().item()}..{boxes.batch_index.max().item()}')


class HandBranch(nn.Module):
    """The paper's hand reconstruction module for N boxes at once.

    Submodules (state-dict prefixes): ``backbone`` (the appearance ViT, WiLoR's names),
    ``adapter``, ``fusion``, ``mano_head``, ``landmark_head`` and ``hand_models`` (left, right).
    """

    def __init__(self, config: HandBranchConfig, feature_dim: int,
                 hand_models: tuple[HandModel, HandModel] | None = None) -> None:
        """Build the branch.

        Args:
            config: hand-branch configuration.
            feature_dim: channels of the backbone patch features (from the geometry branch).
            hand_models: (left, right) hand models; the built-in skeletons if None.

        Raises:
            InputError: if ``hand_models`` are not (left, right).

        """
        super().__init__()
        models = hand_models or (BuiltinHandModel(LEFT), BuiltinHandModel(RIGHT))
        if tuple(model.side for model in models) != (LEFT, RIGHT):
            raise InputError('hand_models: pass the (left, right) models in that order')
        self.config = config
        self.feature_dim = feature_dim
        self.backbone = AppearanceViT(config.appearance, 2.0 / config.default_crop_extent_m)
        self.adapter = GeometricAdapter(config, feature_dim)
        self.fusion = nn.Conv2d(config.adapter_dim + config.appearance.embed_dim,
                                config.fusion_dim, kernel_size=1)
        self.mano_head = ManoHead(config)
        self.landmark_head = LandmarkHead(config)
        self.hand_models = nn.ModuleList(models)

    def forward(self, images: torch.Tensor, features: torch.Tensor, intrinsics: torch.Tensor,
                boxes: HandBoxes) -> HandBranchOutput:
        """Reconstruct the hands in the boxes.

        Args:
            images: (B, 3, H, W) RGB in [0, 1], the model's input images.
            features: (B, C, Hp, Wp) backbone patch features tiling the images.
            intrinsics: (B, 3, 3) K of the input images, pixels.
            boxes: N tight hand boxes with their image index and side.

        Returns:
            Per-box MANO hands in the crop and camera frames, joints and 2D joints.

        Raises:
            InputError: for inconsistent inputs.

        """
        _check_inputs(images, features, intrinsics, boxes, self.feature_dim)
        cameras = build_crop_cameras(boxes.boxes_xyxy.to(intrinsics.dtype),
                                     intrinsics[boxes.batch_index], boxes.sides == LEFT,
                                     self.config.crop_size, self.config.box_expansion)
        crops = warp_to_crop(images, boxes.batch_index, cameras)
        appearance = self.backbone(self._appearance_window(crops))
        geometric = self.adapter(features, boxes.batch_index, cameras,
                                 tuple(images.shape[-2:]))
        fused = self.fusion(torch.cat([geometric, appearance.features], dim=1))
        landmarks, confidence = self.landmark_head(fused)
        mano = self.mano_head(fused, appearance.pose_6d, appearance.betas,
                              self._log_depth_prior(appearance.cam, cameras))
        return self._decode(mano, landmarks, confidence, cameras, boxes.sides)

    def _appearance_window(self, crops: torch.Tensor) -> torch.Tensor:
        """Return the central (h, w) of the canonical crops, the appearance ViT's input."""
        row, col = self.config.appearance_offset
        vit = self.config.appearance
        return crops[..., row:row + vit.image_height, col:col + vit.image_width]

    def _log_depth_prior(self, cam: torch.Tensor, cameras: CropCameras) -> torch.Tensor:
        """Return (N,) ``log t_z`` implied by the coarse weak-perspective scale ``s``.

        A crop of S pixels spanning ``2 / s`` metres at depth t_z with focal ``f^h`` gives
        ``t_z = 2 f^h / (S s)``.
        """
        scale = cam[:, 0].clamp(min=self.config.min_cam_scale)
        focal = cameras.intrinsics[:, 0, 0].to(cam.dtype)
        return torch.log(2.0 * focal / (self.config.crop_size * scale))

    def _translation_free_joints(self, global_orient: torch.Tensor, hand_pose: torch.Tensor,
                                 betas: torch.Tensor, sides: torch.Tensor) -> torch.Tensor:
        """Return (N, 21, 3) joints of each side's hand model with zero translation."""
        joints = global_orient.new_zeros(global_orient.shape[0], NUM_JOINTS, 3)
        for side, model in enumerate(self.hand_models):
            chosen = sides == side
            if chosen.any():
                out = model(global_orient[chosen], hand_pose[chosen], betas[chosen],
                            torch.zeros_like(global_orient[chosen]))
                joints[chosen] = out.joints.to(joints.dtype)
        return joints

    def _decode(self, mano: ManoPrediction, landmarks: torch.Tensor, confidence: torch.Tensor,
                cameras: CropCameras, sides: torch.Tensor) -> HandBranchOutput:
        """Un-flip, pose the hands, solve the translation (eq. 5) and go to the camera (eq. 6)."""
        flipped = cameras.flipped
        orient_h = torch.where(flipped[:, None], mirror_axis_angle(mano.global_orient),
                               mano.global_orient)
        hand_pose = torch.where(flipped[:, None, None], mirror_axis_angle(mano.hand_pose),
                                mano.hand_pose)
        size = self.config.crop_size
        landmarks_px = normalized_to_pixels(flip_normalized(landmarks, flipped), size, size)
        posed = self._translation_free_joints(orient_h, hand_pose, mano.betas, sides)
        root = posed[:, WRIST]
        relative = posed - root[:, None]
        depth = torch.exp(mano.log_depth)
        crop_k = cameras.intrinsics.to(relative.dtype)
        lateral = solve_lateral_translation(relative, landmarks_px.to(relative.dtype), depth,
                                            crop_k)
        wrist_h = torch.cat([lateral, depth[:, None]], dim=1)
        rotation = cameras.rotation_h_from_c.to(relative.dtype)
        orient_c, transl_c = hand_to_camera(orient_h, wrist_h - root, rotation, root)
        joints_cam = (relative + wrist_h[:, None]) @ rotation
        image_k = cameras.image_intrinsics.to(relative.dtype)
        z = joints_cam[..., 2:].clamp(min=MIN_PROJECTION_DEPTH_M)
        rays = torch.cat([joints_cam[..., :2] / z, torch.ones_like(z)], dim=-1)
        joints_2d = (rays @ image_k.transpose(-1, -2))[..., :2]
        return HandBranchOutput(
            cameras=cameras,
            mano_crop=ManoTensors(orient_h, hand_pose, mano.betas, wrist_h - root),
            mano_cam=ManoTensors(orient_c, hand_pose, mano.betas, transl_c),
            root_joint=root, joints_cam=joints_cam, joints_2d=joints_2d,
            landmarks_crop=landmarks, log_depth=mano.log_depth, confidence=confidence)
