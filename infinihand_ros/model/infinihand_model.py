"""The whole InfiniHand model and its camera-space pass, shared by the engine and training.

``InfiniHandModel.forward`` is the paper's per-block pass (Sec. 3.2): the geometry branch
(camera pose encoding, depth, hand masks, patch features) through the stream's memory, the
camera poses and intrinsics decoded from the encodings (given intrinsics win), hand boxes from
the masks (or given boxes, as training does), then the hand branch (crops, appearance encoder,
geometric adapter, fusion, MANO and 2D heads, LSP, eq. 6). Its two halves, ``run_geometry`` and
``run_hands``, are public so a pipelined caller can overlap them; the result is the same.
World placement (eq. 9) is not part of the model: it needs the trajectory's metric scale and BA
corrections, which the engine tracks. State-dict prefixes are ``geometry.`` and ``hand_branch.``.
``build_infinihand_model`` makes a seeded model without touching the caller's random state, and
``load_branch_configs`` resolves config names or paths.
"""

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Final

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import InputError
from infinihand_ros.mano.base import HandModel
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.config import named_config_path
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.geometry_model import GeometryOutput
from infinihand_ros.model.geometry_stream import GeometryStream
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.hand.hand_branch import HandBoxes
from infinihand_ros.model.hand.hand_branch import HandBranch
from infinihand_ros.model.hand.hand_branch import HandBranchOutput
from infinihand_ros.model.heads.mask_head import masks_to_boxes
from infinihand_ros.model.pose_encoding import encoding_to_cam_to_world
from infinihand_ros.model.pose_encoding import FOV_H
import torch
from torch import nn

#: State-dict prefixes of the two branches.
GEOMETRY_PREFIX: Final = 'geometry.'
HAND_BRANCH_PREFIX: Final = 'hand_branch.'
#: State-dict prefix of the hand models' tensors (MANO data when real MANO is used): never saved.
HAND_MODELS_PREFIX: Final = 'hand_branch.hand_models.'


@dataclass(frozen=True)
class HandDetection:
    """How hands are found in the mask head's output (paper Sec. 3.2, appendix A).

    Attributes:
        mask_threshold: a pixel belongs to a hand when its probability exceeds this.
        min_pixels: a mask with fewer hand pixels gives no box.
        presence_threshold: a mask whose peak probability is below this is no detection.
        fov_range_rad: predicted fields of view are clamped to this range (the camera head's
            ReLU allows 0, which no camera has).
        peak_region: box only the connected region around each mask's peak (ours; the paper boxes
            every pixel above the threshold).
        region_join_px: with ``peak_region``, mask fragments up to ``2 * region_join_px + 1``
            model pixels apart count as one region (``mask_head.peak_regions``).

    """

    mask_threshold: float = 0.5
    min_pixels: int = 16
    presence_threshold: float = 0.5
    fov_range_rad: tuple[float, float] = (math.radians(5.0), math.radians(170.0))
    peak_region: bool = False
    region_join_px: int = 0


@dataclass(frozen=True)
class CameraSpaceOutput:
    """The camera-space results of one block of B x S frames (hands indexed over B*S frames).

    Attributes:
        geometry: the geometry branch's outputs (depth and masks at the model size).
        T_world_cam: (B, S, 4, 4) float64 camera-to-world poses, model (scale-free) units, as
            decoded from the pose encodings in the checkpoint's pose direction.
        intrinsics: (B, S, 3, 3) float64 K at the model size used for the hands: the given
            intrinsics where known, else the predicted (FoV-clamped) ones.
        boxes: the hand boxes the hand branch ran on (tight, model pixels), with their frame
            (``batch_index`` over the B*S frames, batch-major) and side.
        presence: (N,) each box's peak mask probability (1.0 for given boxes).
        hands: the hand branch's per-box outputs (camera-frame MANO, joints, 2D joints).

    """

    geometry: GeometryOutput
    T_world_cam: torch.Tensor
    intrinsics: torch.Tensor
    boxes: HandBoxes
    presence: torch.Tensor
    hands: HandBranchOutput


class InfiniHandModel(nn.Module):
    """Geometry branch (camera, depth, hand masks, patch features) + hand branch (MANO hands)."""

    def __init__(self, geometry: GeometryModel, hand_branch: HandBranch) -> None:
        """Hold the two branches; the hand branch reads the geometry branch's patch features.

        Raises:
            ConfigError: when the hand branch expects features of another width.

        """
        super().__init__()
        feature_dim = geometry.config.aggregator.output_dim
        if hand_branch.feature_dim != feature_dim:
            raise ConfigError(f'hand branch built for {hand_branch.feature_dim}-d features, but '
                              f'the geometry branch gives {feature_dim}-d; build it with '
                              'feature_dim=geometry.config.aggregator.output_dim')
        self.geometry = geometry
        self.hand_branch = hand_branch

    def hand_detection(self, presence_threshold: float = 0.5,
                       fov_range_deg: tuple[float, float] = (5.0, 170.0),
                       peak_region: bool = False, region_join_px: int = 0) -> HandDetection:
        """Return detection settings: the geometry config's mask thresholds plus these."""
        masks = self.geometry.config.masks
        return HandDetection(masks.threshold, masks.min_pixels, presence_threshold,
                             (math.radians(fov_range_deg[0]), math.radians(fov_range_deg[1])),
                             peak_region, region_join_px)

    def new_stream(self) -> GeometryStream:
        """Return an empty stream (memories and frame counters) for one sequence."""
        return GeometryStream(self.geometry)

    def forward(self, images: torch.Tensor, stream: GeometryStream,
                keyframe: bool | list[bool] = True, intrinsics: torch.Tensor | None = None,
                intrinsics_known: torch.Tensor | None = None, boxes: HandBoxes | None = None,
                detection: HandDetection | None = None) -> CameraSpaceOutput:
        """Run the camera-space pass on one block of frames.

        Args:
            images: (B, S, 3, H, W) float RGB in [0, 1] at the model size.
            stream: the sequence's stream (from ``new_stream``); the block is added to it.
            keyframe: one flag for all S frames or one per frame (see ``GeometryStream``).
            intrinsics: (B, S, 3, 3) known K at the model size, or None to use the predicted.
            intrinsics_known: (B, S) bool, which of ``intrinsics`` to use (all if None).
            boxes: hand boxes to use instead of the mask head's (training), tight, model
                pixels, ``batch_index`` over the B*S frames.
            detection: thresholds of mask-based detection and the FoV clamp
                (``hand_detection()`` if None).

        Raises:
            InputError: for inputs of the wrong shape.
            ModelOutputError: for non-finite geometry outputs (the stream is left unchanged).

        """
        geometry, T_world_cam, used_intrinsics = self.run_geometry(
            images, stream, keyframe, intrinsics, intrinsics_known, detection)
        return self.run_hands(images, geometry, T_world_cam, used_intrinsics, boxes, detection)

    def run_geometry(self, images: torch.Tensor, stream: GeometryStream,
                     keyframe: bool | list[bool] = True, intrinsics: torch.Tensor | None = None,
                     intrinsics_known: torch.Tensor | None = None,
                     detection: HandDetection | None = None, cpu_bf16: bool = False,
                     masks: bool = True, depth: bool = True
                     ) -> tuple[GeometryOutput, torch.Tensor, torch.Tensor]:
        """Return the geometry outputs, camera-to-world poses and the intrinsics for the hands.

        ``cpu_bf16`` runs the aggregator in bf16 on the CPU (``GeometryModel.forward``); the
        default is the float32 reference path. ``masks=False`` skips the mask head (for hands
        found outside the model; ``run_hands`` then needs given boxes). ``depth=False`` skips the
        depth head (``GeometryModel.frame_depth`` gives a frame's depth on demand).
        """
        detection = detection or self.hand_detection()
        geometry = stream.step(images, keyframe, cpu_bf16, masks, depth)
        height, width = images.shape[-2:]
        encoding = geometry.pose_encoding.double()
        encoding = torch.cat((encoding[..., :FOV_H],  # out of place: training backprops here
                              encoding[..., FOV_H:].clamp(*detection.fov_range_rad)), dim=-1)
        T_world_cam, predicted = encoding_to_cam_to_world(encoding, height, width,
                                                          self.geometry.config.pose_direction)
        if intrinsics is not None:
            given = intrinsics.to(predicted)
            known = (torch.ones(given.shape[:2], dtype=torch.bool, device=given.device)
                     if intrinsics_known is None else intrinsics_known.to(given.device))
            predicted = torch.where(known[..., None, None], given, predicted)
        return geometry, T_world_cam, predicted

    def run_hands(self, images: torch.Tensor, geometry: GeometryOutput, T_world_cam: torch.Tensor,
                  intrinsics: torch.Tensor, boxes: HandBoxes | None = None,
                  detection: HandDetection | None = None) -> CameraSpaceOutput:
        """Find the hands (unless ``boxes`` are given) and run the hand branch on them.

        Raises:
            InputError: without ``boxes`` when the geometry was run without the mask head.

        """
        detection = detection or self.hand_detection()
        features = geometry.patch_features.flatten(0, 1)
        if boxes is None:
            if geometry.hand_masks is None:
                raise InputError('run_hands: the geometry ran without the mask head '
                                 '(masks=False), so there is nothing to find hands in; pass '
                                 'boxes')
            boxes, presence = _detect_hands(geometry.hand_masks.flatten(0, 1), detection)
        else:
            presence = torch.ones(boxes.sides.shape, dtype=features.dtype,
                                  device=features.device)
        hands = self.hand_branch(images.flatten(0, 1), features,
                                 intrinsics.flatten(0, 1).to(features.dtype), boxes)
        return CameraSpaceOutput(geometry, T_world_cam, intrinsics, boxes, presence, hands)


def _detect_hands(masks: torch.Tensor, detection: HandDetection
                  ) -> tuple[HandBoxes, torch.Tensor]:
    """Return the tight boxes of the present hands in (F, 2, H, W) masks and their peaks."""
    peak = masks.amax(dim=(-2, -1))
    tight, valid = masks_to_boxes(masks, detection.mask_threshold, detection.min_pixels,
                                  expand=1.0,  # the hand branch expands boxes itself
                                  peak_region=detection.peak_region,
                                  join_px=detection.region_join_px)
    frame, side = torch.nonzero(valid & (peak > detection.presence_threshold), as_tuple=True)
    return HandBoxes(tight[frame, side], frame, side), peak[frame, side]


def build_infinihand_model(geometry_config: GeometryConfig, hand_config: HandBranchConfig,
                           seed: int = 0,
                           hand_models: tuple[HandModel, HandModel] | None = None
                           ) -> InfiniHandModel:
    """Return a model with seeded initial weights, in train mode on the CPU.

    Args:
        geometry_config: geometry-branch sizes.
        hand_config: hand-branch sizes.
        seed: seed of the weight initialisation (the caller's random state is restored).
        hand_models: (left, right) hand models; the built-in skeletons if None.

    """
    generator_state = torch.random.get_rng_state()
    torch.manual_seed(seed)
    try:
        geometry = GeometryModel(geometry_config)
        hand_branch = HandBranch(hand_config, geometry_config.aggregator.output_dim,
                                 hand_models=hand_models)
    finally:
        torch.random.set_rng_state(generator_state)
    return InfiniHandModel(geometry, hand_branch)


def load_branch_configs(geometry: str | Path,
                        hand_branch: str | Path) -> tuple[GeometryConfig, HandBranchConfig]:
    """Load the two branch configs, each a name ('tiny', 'paper') or a YAML path.

    Raises:
        ConfigError: for an unknown name, a missing file or a bad value.

    """
    text = str(geometry)
    geometry_path = Path(text) if text.endswith(('.yaml', '.yml')) else named_config_path(text)
    return load_geometry_config(geometry_path), load_hand_branch_config(hand_branch)
