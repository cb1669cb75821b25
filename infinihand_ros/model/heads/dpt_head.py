"""DPT decoder (VGGT/LingBot-Map layout) used by the depth head and the mask head.

Four aggregated layers' patch tokens are normalised (``norm``), projected by 1x1 convs
(``projects``) to ``out_channels``, resized to 4x, 2x, 1x and 1/2x of the patch grid
(``resize_layers``; index 2 is an identity with no weights), brought to ``features`` channels
(``scratch.layerN_rn``), fused coarse to fine by RefineNet blocks (``scratch.refinenetN``;
``refinenet4`` has no first residual unit) and decoded at full image resolution by
``scratch.output_conv1`` and ``scratch.output_conv2`` (conv, ReLU, 1x1 conv to ``output_dim``).
A fixed sinusoidal UV embedding (ratio 0.1) is added after projection and after upsampling.
"""

import math

from infinihand_ros.model.config import DptConfig
import torch
from torch import nn
import torch.nn.functional as F

POS_EMBED_RATIO = 0.1
POS_EMBED_OMEGA = 100.0


def uv_embedding(height: int, width: int, channels: int, aspect_ratio: float,
                 device: torch.device) -> torch.Tensor:
    """Return the (channels, height, width) sinusoidal embedding of a normalised UV grid.

    The grid spans the image with the diagonal normalised to 1 (x span = aspect / diagonal);
    half of the channels encode u and half v, each as [sin, cos] of ``uv * omega_k``.
    """
    diagonal = math.hypot(aspect_ratio, 1.0)
    span_x, span_y = aspect_ratio / diagonal, 1.0 / diagonal
    xs = torch.linspace(-span_x * (width - 1) / width, span_x * (width - 1) / width, width,
                        dtype=torch.float64, device=device)
    ys = torch.linspace(-span_y * (height - 1) / height, span_y * (height - 1) / height, height,
                        dtype=torch.float64, device=device)
    quarter = channels // 4
    omega = POS_EMBED_OMEGA ** -(torch.arange(quarter, dtype=torch.float64, device=device)
                                 / quarter)

    def _sincos(values: torch.Tensor) -> torch.Tensor:
        angles = values[..., None] * omega
        return torch.cat((angles.sin(), angles.cos()), dim=-1)

    grid_v, grid_u = torch.meshgrid(ys, xs, indexing='ij')
    embedding = torch.cat((_sincos(grid_u), _sincos(grid_v)), dim=-1)
    return embedding.permute(2, 0, 1).float()


class ResidualConvUnit(nn.Module):
    """relu(x) + conv2(relu(conv1(relu(x)))) with 3x3 convs.

    The residual is ``relu(x)``, not ``x``: upstream (VGGT, LingBot-Map ``ResidualConvUnit``)
    applies an in-place ReLU to its input first, which overwrites the tensor it adds back.
    Trained DPT weights expect exactly that.
    """

    def __init__(self, features: int) -> None:
        """Build two 3x3 convs of width ``features``."""
        super().__init__()
        self.conv1 = nn.Conv2d(features, features, 3, padding=1)
        self.conv2 = nn.Conv2d(features, features, 3, padding=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Return the residual unit's output (same shape as ``x``)."""
        activated = F.relu(x)
        return activated + self.conv2(F.relu(self.conv1(activated)))


class FusionBlock(nn.Module):
    """RefineNet fusion: add the (refined) skip input, refine, upsample, 1x1 conv."""

    def __init__(self, features: int, has_skip: bool) -> None:
        """Build the block; without ``has_skip`` there is no ``resConfUnit1``."""
        super().__init__()
        if has_skip:
            self.resConfUnit1 = ResidualConvUnit(features)
        self.resConfUnit2 = ResidualConvUnit(features)
        self.out_conv = nn.Conv2d(features, features, 1)

    def forward(self, x: torch.Tensor, skip: torch.Tensor | None = None,
                size: tuple[int, int] | None = None) -> torch.Tensor:
        """Return the fused map, upsampled to ``size`` (or 2x when None)."""
        if skip is not None:
            x = x + self.resConfUnit1(skip)
        x = self.resConfUnit2(x)
        if size is None:
            x = F.interpolate(x, scale_factor=2, mode='bilinear', align_corners=True)
        else:
            x = F.interpolate(x, size=size, mode='bilinear', align_corners=True)
        return self.out_conv(x)


class _Scratch(nn.Module):
    """Container of the decoder's fusion stages (its name is part of the state-dict keys)."""

    def __init__(self, out_channels: tuple[int, ...], features: int, head_features: int,
                 output_dim: int) -> None:
        super().__init__()
        for index, channels in enumerate(out_channels, start=1):
            setattr(self, f'layer{index}_rn',
                    nn.Conv2d(channels, features, 3, padding=1, bias=False))
        for index in range(1, len(out_channels) + 1):
            setattr(self, f'refinenet{index}', FusionBlock(features, has_skip=index < 4))
        self.output_conv1 = nn.Conv2d(features, features // 2, 3, padding=1)
        self.output_conv2 = nn.Sequential(
            nn.Conv2d(features // 2, head_features, 3, padding=1), nn.ReLU(inplace=True),
            nn.Conv2d(head_features, output_dim, 1))


class DPTHead(nn.Module):
    """Dense decoder from four aggregated layers to an ``output_dim``-channel full-size map."""

    def __init__(self, config: DptConfig, dim_in: int, output_dim: int) -> None:
        """Build the decoder for ``dim_in``-wide tokens and ``output_dim`` output channels."""
        super().__init__()
        self.config = config
        channels = config.out_channels
        self.norm = nn.LayerNorm(dim_in)
        self.projects = nn.ModuleList(nn.Conv2d(dim_in, out, 1) for out in channels)
        self.resize_layers = nn.ModuleList((
            nn.ConvTranspose2d(channels[0], channels[0], 4, stride=4),
            nn.ConvTranspose2d(channels[1], channels[1], 2, stride=2),
            nn.Identity(),
            nn.Conv2d(channels[3], channels[3], 3, stride=2, padding=1)))
        self.scratch = _Scratch(channels, config.features, config.head_features, output_dim)
        # Channels-last conv weights: oneDNN runs these small-channel convs about 2x faster
        # on the CPU (same values; loading a state dict keeps the layout).
        self.to(memory_format=torch.channels_last)
        # Fixed UV embeddings by (h, w, channels, aspect, device): recomputing the full-size
        # one costs as much as a conv layer per frame.
        self._uv_cache: dict[tuple[int, int, int, float, torch.device], torch.Tensor] = {}

    def forward(self, layers: tuple[torch.Tensor, ...], patch_start: int,
                grid: tuple[int, int], image_size: tuple[int, int]) -> torch.Tensor:
        """Return the raw (pre-activation) map (B, S, output_dim, H, W).

        Args:
            layers: four (B, S, P, C) aggregated layers.
            patch_start: index of the first patch token in each frame.
            grid: patch grid (Hp, Wp).
            image_size: (H, W) of the input images in pixels (multiples of the patch size).

        """
        batch, frames = layers[0].shape[:2]
        height, width = image_size
        maps = []
        for index, tokens in enumerate(layers):
            x = self.norm(tokens[:, :, patch_start:].flatten(0, 1))
            x = x.transpose(1, 2).reshape(batch * frames, -1, *grid)
            x = self._add_uv(self.projects[index](x), width / height)
            maps.append(self.resize_layers[index](x))
        x = self._fuse(maps)
        x = F.interpolate(x, size=(height, width), mode='bilinear', align_corners=True)
        x = self.scratch.output_conv2(self._add_uv(x, width / height))
        return x.reshape(batch, frames, *x.shape[1:])

    def _fuse(self, maps: list[torch.Tensor]) -> torch.Tensor:
        """Return the RefineNet fusion of the four resized maps (coarsest first)."""
        scratch = self.scratch
        rn = [getattr(scratch, f'layer{index}_rn')(x) for index, x in enumerate(maps, start=1)]
        x = scratch.refinenet4(rn[3], size=rn[2].shape[2:])
        x = scratch.refinenet3(x, rn[2], size=rn[1].shape[2:])
        x = scratch.refinenet2(x, rn[1], size=rn[0].shape[2:])
        x = scratch.refinenet1(x, rn[0])
        return scratch.output_conv1(x)

    def _add_uv(self, x: torch.Tensor, aspect_ratio: float) -> torch.Tensor:
        """Add the scaled UV embedding to (N, C, h, w) maps when ``pos_embed`` is on."""
        if not self.config.pos_embed:
            return x
        key = (x.shape[2], x.shape[3], x.shape[1], aspect_ratio, x.device)
        if key not in self._uv_cache:
            self._uv_cache[key] = POS_EMBED_RATIO * uv_embedding(*key)
        return x + self._uv_cache[key].to(x.dtype)


def activate_depth(raw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Return depth = exp(raw[:, :, 0]) and confidence = 1 + exp(raw[:, :, 1]), each (B, S, H, W).

    Depth is in the model's (scale-free) units along the camera z axis.
    """
    return torch.exp(raw[:, :, 0]), 1.0 + torch.exp(raw[:, :, 1])
