"""Patch embeddings of the aggregator: a plain conv, or a DINOv2 ViT with register tokens.

Both map normalised images (B, 3, H, W) to patch tokens (B, Hp * Wp, C), row-major over the patch
grid. Key names follow VGGT/LingBot-Map: ``proj`` for the conv; for DINOv2 ``cls_token``,
``pos_embed``, ``register_tokens``, ``mask_token``, ``patch_embed.proj``, ``blocks.N``, ``norm``.
"""

from infinihand_ros.model.config import AggregatorConfig
from infinihand_ros.model.layers.block import Block
import torch
from torch import nn
import torch.nn.functional as F

DINO_NORM_EPS = 1e-6
INIT_STD = 0.02


class ConvPatchEmbed(nn.Module):
    """One strided convolution: patch_size x patch_size pixels -> one C-d token."""

    def __init__(self, patch_size: int, embed_dim: int) -> None:
        """Build ``proj`` (3 -> embed_dim, kernel and stride ``patch_size``)."""
        super().__init__()
        self.proj = nn.Conv2d(3, embed_dim, kernel_size=patch_size, stride=patch_size)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """Return patch tokens (B, Hp * Wp, C) of normalised images (B, 3, H, W)."""
        return self.proj(images).flatten(2).transpose(1, 2)


class DinoPatchEmbed(nn.Module):
    """DINOv2 ViT with registers whose normalised patch tokens feed the aggregator.

    The positional table covers a square ``pretrain_image_size`` image plus the class token and
    is resized bicubically (with antialiasing) to the actual patch grid.
    """

    def __init__(self, config: AggregatorConfig) -> None:
        """Build the ViT from ``config.patch_embed`` at width ``config.embed_dim``."""
        super().__init__()
        embed = config.patch_embed
        dim = config.embed_dim
        self.pretrain_grid = embed.pretrain_image_size // config.patch_size
        self.num_register_tokens = embed.num_register_tokens
        self.cls_token = nn.Parameter(torch.zeros(1, 1, dim))
        self.pos_embed = nn.Parameter(torch.zeros(1, 1 + self.pretrain_grid ** 2, dim))
        self.register_tokens = nn.Parameter(torch.zeros(1, embed.num_register_tokens, dim))
        # Only used when training with masked patches; kept so DINOv2 weights load by name.
        self.mask_token = nn.Parameter(torch.zeros(1, dim))
        self.patch_embed = ConvPatchEmbed(config.patch_size, dim)
        self.blocks = nn.ModuleList(
            Block(dim, embed.num_heads, embed.mlp_ratio, embed.layer_scale_init,
                  norm_eps=DINO_NORM_EPS)
            for _ in range(embed.depth))
        self.norm = nn.LayerNorm(dim, eps=DINO_NORM_EPS)
        for parameter in (self.cls_token, self.pos_embed, self.register_tokens):
            nn.init.trunc_normal_(parameter, std=INIT_STD)

    def _positional(self, grid: tuple[int, int], dtype: torch.dtype) -> torch.Tensor:
        """Return the positional embedding (1, 1 + Hp * Wp, C) for a patch ``grid``."""
        table = self.pos_embed.float()
        if grid == (self.pretrain_grid, self.pretrain_grid):
            return table.to(dtype)
        side = self.pretrain_grid
        patches = table[:, 1:].reshape(1, side, side, -1).permute(0, 3, 1, 2)
        patches = F.interpolate(patches, size=grid, mode='bicubic', antialias=True,
                                align_corners=False)
        patches = patches.permute(0, 2, 3, 1).flatten(1, 2)
        return torch.cat((table[:, :1], patches), dim=1).to(dtype)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """Return normalised patch tokens (B, Hp * Wp, C) of normalised images (B, 3, H, W)."""
        batch, _, height, width = images.shape
        patch = self.patch_embed.proj.stride[0]
        tokens = self.patch_embed(images)
        tokens = torch.cat((self.cls_token.expand(batch, -1, -1).to(tokens.dtype), tokens), dim=1)
        tokens = tokens + self._positional((height // patch, width // patch), tokens.dtype)
        registers = self.register_tokens.expand(batch, -1, -1).to(tokens.dtype)
        tokens = torch.cat((tokens[:, :1], registers, tokens[:, 1:]), dim=1)
        for block in self.blocks:
            tokens = block(tokens)
        return self.norm(tokens)[:, 1 + self.num_register_tokens:]


def build_patch_embed(config: AggregatorConfig) -> nn.Module:
    """Return the patch embedding named by ``config.patch_embed.kind``."""
    if config.patch_embed.kind == 'dinov2':
        return DinoPatchEmbed(config)
    return ConvPatchEmbed(config.patch_size, config.embed_dim)
