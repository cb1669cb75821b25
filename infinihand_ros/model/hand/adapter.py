"""Geometric adapter: backbone patch features cropped through the crop warp and re-embedded.

The geometry branch's patch features tile the model's input image (one cell per ``p x p``
pixels). For each hand box the adapter samples them, bilinearly, at the centres of the appearance
ViT's patches, mapped through the same canonical crop warp as the RGB crop (so left hands are
mirrored here too), then re-embeds them on the crop's patch grid: LayerNorm, a two-layer MLP to
``adapter_dim`` and a learned position embedding of the crop grid. The result G lines up token
for token with the appearance features A.
"""

from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.hand.crop_camera import CropCameras
from infinihand_ros.model.hand.crop_camera import sample_at_crop_pixels
import torch
from torch import nn
import torch.nn.functional as F

#: Standard deviation of the position embedding's truncated-normal initialisation.
_POS_INIT_STD = 0.02


def appearance_patch_centres(config: HandBranchConfig) -> torch.Tensor:
    """Return (Gh * Gw, 2) canonical crop pixels (u, v) at the centres of the ViT's patches.

    The centre of a patch is the centre of its padded convolution window, row-major like the
    ViT's tokens.
    """
    vit = config.appearance
    row0, col0 = config.appearance_offset
    grid_h, grid_w = vit.grid_size
    shift = -vit.patch_padding + 0.5 * (vit.patch_size - 1)
    v = row0 + shift + vit.patch_size * torch.arange(grid_h, dtype=torch.float64)
    u = col0 + shift + vit.patch_size * torch.arange(grid_w, dtype=torch.float64)
    vv, uu = torch.meshgrid(v, u, indexing='ij')
    return torch.stack([uu.flatten(), vv.flatten()], dim=-1)


class GeometricAdapter(nn.Module):
    """Crop and re-embed backbone patch features on the crop's patch grid (the paper's A)."""

    def __init__(self, config: HandBranchConfig, feature_dim: int) -> None:
        """Build the re-embedding.

        Args:
            config: hand-branch configuration (grid, ``adapter_dim``).
            feature_dim: channels C of the backbone patch features.

        """
        super().__init__()
        self.grid_size = config.appearance.grid_size
        dim = config.adapter_dim
        self.norm = nn.LayerNorm(feature_dim)
        self.fc1 = nn.Linear(feature_dim, dim)
        self.fc2 = nn.Linear(dim, dim)
        self.pos_embed = nn.Parameter(torch.zeros(1, self.grid_size[0] * self.grid_size[1], dim))
        nn.init.trunc_normal_(self.pos_embed, std=_POS_INIT_STD)
        self.register_buffer('patch_centres', appearance_patch_centres(config), persistent=False)

    def forward(self, features: torch.Tensor, batch_index: torch.Tensor, cameras: CropCameras,
                image_size: tuple[int, int]) -> torch.Tensor:
        """Return G (N, adapter_dim, Gh, Gw) for N boxes.

        Args:
            features: (B, C, Hp, Wp) backbone patch features tiling the (H, W) image.
            batch_index: (N,) long, the image of each box.
            cameras: the N crop cameras.
            image_size: (H, W) of the image, pixels.

        """
        sampled = sample_at_crop_pixels(features, batch_index, cameras, self.patch_centres,
                                        image_size)
        tokens = self.fc2(F.gelu(self.fc1(self.norm(sampled.transpose(1, 2))))) + self.pos_embed
        return tokens.transpose(1, 2).reshape(*tokens.shape[::2], *self.grid_size)
