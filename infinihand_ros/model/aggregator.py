"""Aggregator: patch embedding, special tokens and alternating frame / global attention.

Tokens per frame: camera (1), registers (R), scale (1), then the Hp x Wp patches (row-major), so
the patches start at index R + 2. Frame blocks attend within each frame with 2D RoPE; global
blocks attend across frames through the streaming memory with the 3D video RoPE (or 2D RoPE for
VGGT weights). Each special-token parameter has two slots (shape (1, 2, n, C)): slot 0 for the
first frame of the sequence (camera, registers) or for the anchor frames (scale), slot 1 for
every later frame. Key names mirror LingBot-Map's ``aggregator.*``.
"""

from dataclasses import dataclass

from infinihand_ros.model.config import AggregatorConfig
from infinihand_ros.model.layers.block import Block
from infinihand_ros.model.layers.patch_embed import build_patch_embed
from infinihand_ros.model.layers.rope import frame_positions
from infinihand_ros.model.layers.rope import Rotary
from infinihand_ros.model.layers.rope import rotary_2d
from infinihand_ros.model.layers.rope import rotary_3d
from infinihand_ros.model.layers.rope import video_positions
from infinihand_ros.model.streaming_memory import BlockPlan
from infinihand_ros.model.streaming_memory import KVMemory
import torch
from torch import nn

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
TOKEN_INIT_STD = 1e-6


@dataclass(frozen=True)
class AggregatorOutput:
    """Aggregated tokens of the selected layers.

    Attributes:
        layers: one (B, S, P, 2C) tensor per selected layer (frame and global outputs
            concatenated); P = patch_start + Hp * Wp.
        patch_start: index of the first patch token in each frame.
        grid: patch grid (Hp, Wp).

    """

    layers: tuple[torch.Tensor, ...]
    patch_start: int
    grid: tuple[int, int]


class Aggregator(nn.Module):
    """LingBot-Map's streaming aggregator with every size taken from ``AggregatorConfig``."""

    def __init__(self, config: AggregatorConfig) -> None:
        """Build the tokens, patch embedding and 2 x ``depth`` blocks."""
        super().__init__()
        self.config = config
        dim = config.embed_dim
        self.camera_token = nn.Parameter(torch.empty(1, 2, 1, dim))
        self.register_token = nn.Parameter(torch.empty(1, 2, config.num_register_tokens, dim))
        self.scale_token = nn.Parameter(torch.empty(1, 2, 1, dim))
        for token in (self.camera_token, self.register_token, self.scale_token):
            nn.init.normal_(token, std=TOKEN_INIT_STD)
        self.patch_embed = build_patch_embed(config)
        self.frame_blocks = nn.ModuleList(self._block() for _ in range(config.depth))
        self.global_blocks = nn.ModuleList(self._block() for _ in range(config.depth))
        self.register_buffer('_mean', torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1),
                             persistent=False)
        self.register_buffer('_std', torch.tensor(IMAGENET_STD).view(1, 3, 1, 1),
                             persistent=False)

    def _block(self) -> Block:
        config = self.config
        return Block(config.embed_dim, config.num_heads, config.mlp_ratio,
                     config.layer_scale_init, qk_norm=config.qk_norm)

    @property
    def patch_start(self) -> int:
        """Return the index of the first patch token of a frame."""
        return self.config.num_special_tokens

    def forward(self, images: torch.Tensor, plan: BlockPlan, memory: KVMemory
                ) -> AggregatorOutput:
        """Aggregate one block of frames through the streaming memory.

        Args:
            images: (B, S, 3, H, W) RGB in [0, 1]; H and W multiples of the patch size.
            plan: the block's plan from the stream's ``FrameSchedule`` (S frames).
            memory: the global blocks' memory (``depth`` layers); ``begin`` is called here,
                ``commit`` by the caller once the block's outputs are accepted.

        Returns:
            The selected layers' tokens (see ``AggregatorOutput``).

        """
        batch, frames, _, height, width = images.shape
        grid = (height // self.config.patch_size, width // self.config.patch_size)
        tokens = self._embed(images, plan, grid)
        per_frame = tokens.shape[1]
        frame_rope, global_rope = self._rotaries(plan, grid, images.device)
        memory.begin(plan, per_frame, images.device)
        selected = set(self.config.selected_layers)
        outputs = {}
        for index, (frame_block, global_block) in enumerate(
                zip(self.frame_blocks, self.global_blocks)):
            tokens = frame_block(tokens, rope=frame_rope)
            frame_out = tokens
            tokens = global_block(tokens.reshape(batch, frames * per_frame, -1), rope=global_rope,
                                  context=memory.context(index))
            tokens = tokens.reshape(batch * frames, per_frame, -1)
            if index in selected:
                outputs[index] = (torch.cat((frame_out, tokens), dim=-1)
                                  .reshape(batch, frames, per_frame, -1))
        return AggregatorOutput(tuple(outputs[index] for index in self.config.selected_layers),
                                self.patch_start, grid)

    def _embed(self, images: torch.Tensor, plan: BlockPlan, grid: tuple[int, int]
               ) -> torch.Tensor:
        """Return (B*S, P, C) tokens: special tokens then patch tokens of each frame."""
        batch, frames = images.shape[:2]
        pixels = (images.flatten(0, 1) - self._mean) / self._std
        patches = self.patch_embed(pixels)
        sequence_index = torch.arange(plan.first_frame, plan.first_frame + frames,
                                      device=images.device)
        first_slot = (sequence_index > 0).long()
        scale_slot = torch.full_like(sequence_index, 0 if plan.is_anchor else 1)
        specials = torch.cat((self.camera_token[0, first_slot], self.register_token[0, first_slot],
                              self.scale_token[0, scale_slot]), dim=1)
        specials = specials.to(patches.dtype).repeat(batch, 1, 1)
        return torch.cat((specials, patches), dim=1)

    def _rotaries(self, plan: BlockPlan, grid: tuple[int, int], device: torch.device
                  ) -> tuple[Rotary, Rotary]:
        """Return the frame blocks' 2D RoPE (one frame) and the global blocks' RoPE (S frames)."""
        config = self.config
        head_dim = config.embed_dim // config.num_heads
        positions = frame_positions(grid, self.patch_start, device)
        frame_rope = rotary_2d(positions, head_dim, config.rope_frequency)
        if config.global_rope == 'spatial2d':
            return frame_rope, frame_rope.repeat(plan.num_frames)
        times = torch.tensor(plan.time_index, dtype=torch.long, device=device)
        global_rope = rotary_3d(video_positions(grid, self.patch_start, times),
                                config.rope3d_split, config.rope3d_theta)
        return frame_rope, global_rope
