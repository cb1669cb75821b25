"""The geometry branch put together: aggregator, causal camera head, DPT depth and mask heads.

Attribute names (``aggregator``, ``camera_head``, ``depth_head``) mirror LingBot-Map so its
checkpoint loads by identity; ``mask_head`` is ours (paper Sec. 3.2). The aggregator runs in
bf16 autocast on CUDA (when configured) and, when a call asks for ``cpu_bf16``, on the CPU (for
CPUs with native bf16, ``cpu_bf16_supported``); the heads run in float32. float32 everywhere on
the CPU is the reference path (the default). A call may skip the depth head
(``depth=False``) and keep the aggregated tokens instead, so a caller computes depth only for
the frames that need it (``frame_depth``); each frame's depth is the same either way.
"""

from dataclasses import dataclass

from infinihand_ros.model.aggregator import Aggregator
from infinihand_ros.model.aggregator import AggregatorOutput
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.heads.camera_head import CameraHead
from infinihand_ros.model.heads.dpt_head import activate_depth
from infinihand_ros.model.heads.dpt_head import DPTHead
from infinihand_ros.model.heads.mask_head import activate_masks
from infinihand_ros.model.heads.mask_head import init_mask_head_from_depth
from infinihand_ros.model.heads.mask_head import NUM_MASK_CHANNELS
from infinihand_ros.model.streaming_memory import BlockPlan
from infinihand_ros.model.streaming_memory import KVMemory
import torch
from torch import nn

DEPTH_CHANNELS = 2  # depth, confidence


def cpu_bf16_supported() -> bool:
    """Return whether this CPU computes bf16 natively (AVX512-BF16 or AMX tiles)."""
    return bool(torch.cpu._is_avx512_bf16_supported() or torch.cpu._is_amx_tile_supported())


def _dense(head: DPTHead, layers: tuple[torch.Tensor, ...], aggregated: AggregatorOutput,
           image_size: tuple[int, int]) -> torch.Tensor:
    """Run a dense head on (B, S, P, C) layers; on the CPU frame by frame.

    A frame's full-size maps stay in the CPU's caches; a window's batch of them does not (the
    heads ran ~1.3x slower per frame on a 16-frame window). Each frame's result is its batch-1
    result, as in per-frame streaming.
    """
    if layers[0].device.type != 'cpu':
        return head(layers, aggregated.patch_start, aggregated.grid, image_size)
    return torch.cat([head(tuple(layer[:, frame:frame + 1] for layer in layers),
                           aggregated.patch_start, aggregated.grid, image_size)
                      for frame in range(layers[0].shape[1])], dim=1)


@dataclass(frozen=True)
class DenseInput:
    """What a dense head needs for a block's frames: the float32 tokens and the image size."""

    tokens: AggregatorOutput
    image_size: tuple[int, int]


@dataclass(frozen=True)
class GeometryOutput:
    """Per-frame outputs of one block of S frames.

    Attributes:
        pose_encoding: (B, S, 9) final camera encoding (see ``model/pose_encoding.py``).
        pose_encoding_iterations: the camera head's encodings of every refinement pass.
        depth: (B, S, H, W) depth along the camera z axis, model units (no metric scale), or
            None when the call skipped the depth head (``depth=False``; see ``dense_input``).
        depth_conf: (B, S, H, W) confidence >= 1, or None with ``depth``.
        hand_masks: (B, S, 2, H, W) left/right hand probabilities in [0, 1], or None when
            the call skipped the mask head (``masks=False``: hands found outside the model).
        patch_features: (B, S, 2C, Hp, Wp) the last selected aggregator layer's patch tokens
            (frame and global outputs concatenated) on the patch grid; pixel (u, v) lies in
            cell (v // patch_size, u // patch_size). This is what the hand branch crops.
        patch_size: pixels per patch side.
        dense_input: the tokens ``GeometryModel.frame_depth`` computes a frame's depth from,
            when the call skipped the depth head; else None.

    """

    pose_encoding: torch.Tensor
    pose_encoding_iterations: tuple[torch.Tensor, ...]
    depth: torch.Tensor | None
    depth_conf: torch.Tensor | None
    hand_masks: torch.Tensor | None
    patch_features: torch.Tensor
    patch_size: int
    dense_input: DenseInput | None = None


class GeometryModel(nn.Module):
    """LingBot-Map-shaped geometry branch plus the hand mask head."""

    def __init__(self, config: GeometryConfig) -> None:
        """Build every part from ``config``; the mask head starts from the depth head."""
        super().__init__()
        self.config = config
        dim = config.aggregator.output_dim
        self.aggregator = Aggregator(config.aggregator)
        self.camera_head = CameraHead(config.camera_head, dim)
        self.depth_head = DPTHead(config.dpt, dim, DEPTH_CHANNELS)
        self.mask_head = DPTHead(config.dpt, dim, NUM_MASK_CHANNELS)
        if not self.depth_head.norm.weight.is_meta:
            init_mask_head_from_depth(self.mask_head, self.depth_head)

    def new_memories(self) -> tuple[KVMemory, KVMemory]:
        """Return empty (aggregator, camera head) memories sized for this model."""
        aggregator, memory = self.config.aggregator, self.config.memory
        return (KVMemory(aggregator.depth, memory.window, aggregator.num_special_tokens,
                         memory.max_trajectory_frames),
                KVMemory(self.camera_head.memory_layers, memory.max_trajectory_frames,
                         aggregator.num_special_tokens, memory.max_trajectory_frames))

    def forward(self, images: torch.Tensor, plan: BlockPlan, aggregator_memory: KVMemory,
                camera_memory: KVMemory, cpu_bf16: bool = False,
                masks: bool = True, depth: bool = True) -> GeometryOutput:
        """Run one block of frames.

        Args:
            images: (B, S, 3, H, W) RGB in [0, 1], H and W multiples of the patch size.
            plan: the block's plan (see ``streaming_memory.FrameSchedule``).
            aggregator_memory: memory of the global blocks (from ``new_memories``).
            camera_memory: the camera head's causal memory (from ``new_memories``).
            cpu_bf16: on the CPU, run the aggregator in bf16 autocast too (when the config's
                ``autocast_bf16`` is set); False: the float32 reference path. Ask for it only
                where ``cpu_bf16_supported()`` (elsewhere bf16 is emulated, slowly).
            masks: run the mask head; False skips it (``hand_masks`` is None), for callers
                whose hands come from elsewhere.
            depth: run the depth head; False skips it (``depth`` is None) and keeps the tokens
                in ``dense_input`` for ``frame_depth``.

        """
        autocast = self.config.autocast_bf16 and (
            images.device.type == 'cuda' or (images.device.type == 'cpu' and cpu_bf16))
        with torch.autocast(images.device.type, dtype=torch.bfloat16, enabled=autocast):
            aggregated = self.aggregator(images, plan, aggregator_memory)
        with torch.autocast(images.device.type, enabled=False):
            layers = tuple(layer.float() for layer in aggregated.layers)
            encodings = self.camera_head(layers[-1], plan, camera_memory)
            image_size = tuple(images.shape[-2:])
            depth_map, depth_conf = (activate_depth(
                _dense(self.depth_head, layers, aggregated, image_size)) if depth
                else (None, None))
            hand_masks = (activate_masks(_dense(self.mask_head, layers, aggregated, image_size))
                          if masks else None)
        patches = layers[-1][:, :, aggregated.patch_start:]
        features = patches.transpose(2, 3).unflatten(-1, aggregated.grid)
        dense_input = None if depth else DenseInput(
            AggregatorOutput(layers, aggregated.patch_start, aggregated.grid), image_size)
        return GeometryOutput(encodings[-1], tuple(encodings), depth_map, depth_conf, hand_masks,
                              features, self.config.aggregator.patch_size, dense_input)

    def frame_depth(self, dense: DenseInput, frame: int, batch: int = 0) -> torch.Tensor:
        """Return one frame's (H, W) depth (model units) from a call's skipped-head tokens."""
        layers = tuple(layer[batch:batch + 1, frame:frame + 1] for layer in dense.tokens.layers)
        with torch.autocast(layers[0].device.type, enabled=False):
            depth, _ = activate_depth(self.depth_head(layers, dense.tokens.patch_start,
                                                      dense.tokens.grid, dense.image_size))
        return depth[0, 0]
