"""One training forward pass over a batch of clips: the model, window by window, then the losses.

``ClipRunner`` is the module a run optimises (and DistributedDataParallel wraps, so a whole
clip, however many windows, is one forward and one backward). Per clip batch it starts a fresh
stream (state reset between clips), runs the anchor block and then each window through the
shared paper-level pass (``InfiniHandModel.run_geometry`` then ``run_hands``, the two halves of
``forward``, split so the boxes can be chosen from the window's own predicted masks), carrying
the streaming state across the windows; the cameras are ``run_geometry``'s (the engine's
decoding). Each visible annotated hand runs on its ground-truth
box or, with probability ``1 - gt_box_ratio`` (the caller's draw), on the box of the predicted
mask of its side when there is one (paper Stage II: 1 : 1). Then ``loss_adapter`` computes the
configured loss groups. On CUDA the pass runs as the engine runs it: the aggregator in bf16
autocast (the geometry config's ``autocast_bf16``), the heads and the hand branch (crop-camera
geometry, LSP) in float32, where bf16 would cost pixels.
"""

from typing import Final

from infinihand_ros.model.geometry_stream import GeometryStream
from infinihand_ros.model.hand.hand_branch import HandBoxes
from infinihand_ros.model.hand.hand_branch import HandBranchOutput
from infinihand_ros.model.heads.mask_head import masks_to_boxes
from infinihand_ros.model.infinihand_model import HandDetection
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.train import sequence_reader as keys
from infinihand_ros.train.loss_adapter import ClipPredictions
from infinihand_ros.train.loss_adapter import compute_loss_groups
from infinihand_ros.train.loss_adapter import crop_landmark_targets
from infinihand_ros.train.loss_adapter import scatter_hands
from infinihand_ros.train.loss_adapter import total_and_terms
from infinihand_ros.train.train_config import TrainConfig
import torch
from torch import nn

#: Key of L_joint in the runner's output.
LOSS: Final = 'loss'


def predicted_boxes(masks: torch.Tensor, detection: HandDetection
                    ) -> tuple[torch.Tensor, torch.Tensor]:
    """Return tight boxes (F, 2, 4) and detected (F, 2) of hand probabilities (F, 2, H, W)."""
    with torch.no_grad():
        tight, valid = masks_to_boxes(masks, detection.mask_threshold, detection.min_pixels,
                                      expand=1.0, peak_region=detection.peak_region)
        peak = masks.amax(dim=(-2, -1))
    return tight, valid & (peak > detection.presence_threshold)


def choose_boxes(gt_boxes: torch.Tensor, gt_valid: torch.Tensor, pred_boxes: torch.Tensor,
                 pred_valid: torch.Tensor, use_gt: torch.Tensor) -> HandBoxes:
    """Return one box per visible hand: ground truth where ``use_gt`` or nothing was detected.

    Args:
        gt_boxes: (F, 2, 4) annotated tight boxes, model pixels.
        gt_valid: (F, 2) bool, the hand is visible.
        pred_boxes: (F, 2, 4) boxes of the predicted masks.
        pred_valid: (F, 2) bool, the mask of that side gave a detection.
        use_gt: (F, 2) bool draws.

    """
    take_gt = use_gt | ~pred_valid
    boxes = torch.where(take_gt[..., None], gt_boxes, pred_boxes.to(gt_boxes.dtype))
    frame, side = torch.nonzero(gt_valid, as_tuple=True)
    return HandBoxes(boxes[frame, side], frame, side)


class ClipRunner(nn.Module):
    """Runs a batch of clips through the model and returns L_joint and its terms."""

    def __init__(self, model: InfiniHandModel, config: TrainConfig,
                 detection: HandDetection | None = None) -> None:
        """Wrap ``model`` for the run ``config`` (layout, loss groups and weights)."""
        super().__init__()
        self.model = model
        self.config = config
        self.detection = detection or model.hand_detection(
            peak_region=config.peak_region_boxes)

    def forward(self, batch: dict[str, torch.Tensor], use_gt: torch.Tensor
                ) -> dict[str, torch.Tensor]:
        """Return ``{'loss': L_joint, term name: value}`` of a batch (on the model's device).

        Args:
            batch: a ``ClipLoader`` batch already on the model's device.
            use_gt: (B, S, 2) bool, which hands run on their ground-truth box.

        """
        pred = self._predict(batch, use_gt)
        groups = compute_loss_groups(pred, batch, self.config.loss_groups, self.config.losses,
                                     self.config.mask_logit_eps, self.config.clip.frame_stride)
        total, terms = total_and_terms(groups)
        return {LOSS: total, **terms}

    def _predict(self, batch: dict[str, torch.Tensor], use_gt: torch.Tensor
                 ) -> ClipPredictions:
        """Run the anchors and every window of the clips with one stream; join the outputs."""
        stream = self.model.new_stream()
        images = batch[keys.IMAGES].float() / 255.0
        parts = [self._run_block(images[:, start:end], batch, start, end, use_gt, stream)
                 for start, end in self.config.clip.blocks]
        return ClipPredictions(*(torch.cat(values, dim=1) for values in zip(*parts)))

    def _run_block(self, images: torch.Tensor, batch: dict[str, torch.Tensor], start: int,
                   end: int, use_gt: torch.Tensor, stream: GeometryStream
                   ) -> tuple[torch.Tensor, ...]:
        """Run clip frames [start, end) and return their dense predictions (ClipPredictions)."""
        batch_size, frames = images.shape[:2]
        geometry, T_world_cam, used_intrinsics = self.model.run_geometry(
            images, stream, True, None, None, self.detection)
        if self.config.use_gt_intrinsics:
            used_intrinsics = batch[keys.INTRINSICS][:, start:end]
        masks = geometry.hand_masks.flatten(0, 1)
        pred_boxes, pred_valid = predicted_boxes(masks.detach(), self.detection)
        valid = batch[keys.BOX_VALID][:, start:end].flatten(0, 1)
        boxes = choose_boxes(batch[keys.BOXES][:, start:end].flatten(0, 1), valid, pred_boxes,
                             pred_valid, use_gt[:, start:end].flatten(0, 1))
        output = self.model.run_hands(images, geometry, T_world_cam, used_intrinsics, boxes,
                                      self.detection)
        hands = _dense_hands(output.hands, boxes,
                             batch[keys.JOINTS_CAM][:, start:end].flatten(0, 1),
                             batch_size * frames)

        def unflat(value: torch.Tensor) -> torch.Tensor:
            return value.unflatten(0, (batch_size, frames))

        return (geometry.pose_encoding, T_world_cam, used_intrinsics, geometry.hand_masks,
                *(unflat(value) for value in hands), geometry.depth, geometry.depth_conf)


def _dense_hands(hands: HandBranchOutput, boxes: HandBoxes, joints_cam: torch.Tensor,
                 frames: int) -> tuple[torch.Tensor, ...]:
    """Return (ran, MANO x 4, joints, landmarks, landmark targets), each (F, 2, ...)."""
    frame, side = boxes.batch_index, boxes.sides
    ran = torch.zeros((frames, 2), dtype=torch.bool, device=frame.device)
    ran[frame, side] = True
    targets = crop_landmark_targets(joints_cam[frame, side], hands.cameras)
    mano = hands.mano_cam
    values = (mano.global_orient, mano.hand_pose, mano.betas, mano.transl, hands.joints_cam,
              hands.landmarks_crop, targets)
    return (ran, *(scatter_hands(value, frame, side, frames) for value in values))
