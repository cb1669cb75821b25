"""Causal camera head: iterative refinement of the 9-number pose encoding from camera tokens.

Input is each frame's camera token of the last selected aggregator layer. Each of
``num_iterations`` passes embeds the previous (detached) encoding, or the learned
``empty_pose_tokens`` on the first pass, modulates the normalised tokens with it (adaLN: shift,
scale, gate), runs the trunk blocks (causal attention across frames through the head's own
memory, one token per frame) and adds the predicted delta. Key names mirror LingBot-Map's
``camera_head.*``; the encoding is described in ``model/pose_encoding.py``.
"""

from infinihand_ros.model.config import CameraHeadConfig
from infinihand_ros.model.layers.block import Block
from infinihand_ros.model.layers.block import Mlp
from infinihand_ros.model.pose_encoding import activate_pose
from infinihand_ros.model.pose_encoding import POSE_ENCODING_SIZE
from infinihand_ros.model.streaming_memory import BlockPlan
from infinihand_ros.model.streaming_memory import KVMemory
import torch
from torch import nn

ADALN_EPS = 1e-6


class CameraHead(nn.Module):
    """Camera-token trunk with adaLN modulation and a pose MLP, refined iteratively."""

    def __init__(self, config: CameraHeadConfig, dim_in: int) -> None:
        """Build the head for ``dim_in``-wide aggregated tokens."""
        super().__init__()
        self.config = config
        self.empty_pose_tokens = nn.Parameter(torch.zeros(1, 1, POSE_ENCODING_SIZE))
        self.trunk = nn.ModuleList(
            Block(dim_in, config.num_heads, config.mlp_ratio, config.layer_scale_init)
            for _ in range(config.trunk_depth))
        self.token_norm = nn.LayerNorm(dim_in)
        self.trunk_norm = nn.LayerNorm(dim_in)
        self.embed_pose = nn.Linear(POSE_ENCODING_SIZE, dim_in)
        self.poseLN_modulation = nn.Sequential(nn.SiLU(), nn.Linear(dim_in, 3 * dim_in))
        self.adaln_norm = nn.LayerNorm(dim_in, elementwise_affine=False, eps=ADALN_EPS)
        self.pose_branch = Mlp(dim_in, dim_in // 2, POSE_ENCODING_SIZE)

    @property
    def memory_layers(self) -> int:
        """Return the attention layers of the head's causal memory (iterations x trunk)."""
        return self.config.num_iterations * self.config.trunk_depth

    def forward(self, tokens: torch.Tensor, plan: BlockPlan, memory: KVMemory
                ) -> list[torch.Tensor]:
        """Return the activated encodings (B, S, 9) of every iteration (last = final).

        Args:
            tokens: (B, S, P, C) last selected aggregator layer; the camera token is index 0.
            plan: the block's plan (S frames).
            memory: ``memory_layers``-layer memory with ``window=None``; ``begin`` is called
                here, ``commit`` by the caller once the block's outputs are accepted.

        """
        camera = self.token_norm(tokens[:, :, 0])
        memory.begin(plan, 1, tokens.device)
        raw = None
        encodings = []
        for iteration in range(self.config.num_iterations):
            source = (self.empty_pose_tokens.expand(*camera.shape[:2], -1) if raw is None
                      else raw.detach())
            shift, scale, gate = self.poseLN_modulation(self.embed_pose(source)).chunk(3, dim=-1)
            x = gate * (self.adaln_norm(camera) * (1 + scale) + shift) + camera
            for depth, block in enumerate(self.trunk):
                layer = iteration * self.config.trunk_depth + depth
                x = block(x, context=memory.context(layer))
            delta = self.pose_branch(self.trunk_norm(x))
            raw = delta if raw is None else raw + delta
            encodings.append(activate_pose(raw))
        return encodings
