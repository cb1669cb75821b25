"""Configuration of the hand branch: crop camera, WiLoR-named appearance ViT, adapter and heads.

Values live in ``config/hand_branch_paper.yaml`` (WiLoR sizes, so a WiLoR checkpoint initialises
the appearance encoder) and ``config/hand_branch_tiny.yaml`` (CPU, tests, demo), section
``hand_branch``. The width of the backbone features is not configured here: it comes from the
geometry branch (``HandBranch(config, feature_dim=...)``).
"""

from dataclasses import dataclass
from dataclasses import field
from pathlib import Path
from typing import Final

from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import load_config
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError

#: Top-level key of the hand-branch section in the YAML files.
CONFIG_SECTION: Final = 'hand_branch'
#: Names of the shipped configurations (``config/hand_branch_<name>.yaml``).
CONFIG_NAMES: Final = ('paper', 'tiny')


@dataclass(frozen=True)
class AppearanceViTConfig:
    """Sizes of the appearance ViT (WiLoR's ViTPose-style backbone).

    Attributes:
        image_height: input height in pixels (WiLoR: 256).
        image_width: input width in pixels, the central columns of the square crop (WiLoR: 192).
        patch_size: patch (kernel and stride) of the patch embedding, pixels (WiLoR: 16).
        patch_padding: zero padding of the patch-embedding convolution, pixels (WiLoR: 2).
        embed_dim: token width (WiLoR ViT-H: 1280).
        depth: number of transformer blocks (WiLoR: 32).
        num_heads: attention heads (WiLoR: 16).
        mlp_ratio: hidden width of the MLP over the token width (WiLoR: 4).
        qkv_bias: bias in the query/key/value projection (WiLoR: True).
        norm_eps: LayerNorm epsilon (WiLoR: 1e-6).

    """

    image_height: int = 256
    image_width: int = 192
    patch_size: int = 16
    patch_padding: int = 2
    embed_dim: int = 1280
    depth: int = 32
    num_heads: int = 16
    mlp_ratio: float = 4.0
    qkv_bias: bool = True
    norm_eps: float = 1e-6

    def __post_init__(self) -> None:
        """Reject sizes that do not tile into patches or heads (ConfigError)."""
        owner = f'{CONFIG_SECTION}.appearance'
        require_positive(owner, image_height=self.image_height, image_width=self.image_width,
                         patch_size=self.patch_size, embed_dim=self.embed_dim, depth=self.depth,
                         num_heads=self.num_heads, mlp_ratio=self.mlp_ratio,
                         norm_eps=self.norm_eps)
        if self.image_height % self.patch_size or self.image_width % self.patch_size:
            raise ConfigError(
                f'{owner}: image {self.image_height}x{self.image_width} is not a multiple of '
                f'patch_size {self.patch_size}; choose sizes divisible by the patch')
        if not 0 <= 2 * self.patch_padding < self.patch_size:
            raise ConfigError(f'{owner}.patch_padding: need 0 <= 2 * padding < patch_size '
                              f'({self.patch_size}), got {self.patch_padding}')
        if self.embed_dim % self.num_heads:
            raise ConfigError(f'{owner}: embed_dim {self.embed_dim} is not divisible by '
                              f'num_heads {self.num_heads}')

    @property
    def grid_size(self) -> tuple[int, int]:
        """Return the token grid (rows, columns) of the image patches."""
        return self.image_height // self.patch_size, self.image_width // self.patch_size


@dataclass(frozen=True)
class HandBranchConfig:
    """Hand branch sizes and crop settings.

    Attributes:
        crop_size: side of the square perspective crop, pixels (paper: 256).
        box_expansion: the crop covers this factor times the longer side of the tight hand box
            (the paper's design: 1.5).
        default_crop_extent_m: metric width the crop covers when the coarse camera of the
            appearance encoder is at its default (sets the ``init_cam`` buffer before a WiLoR
            checkpoint overrides it, and so the initial depth ``t_z``).
        min_cam_scale: floor of the coarse weak-perspective scale when it becomes a depth prior.
        adapter_dim: width of the re-embedded geometric features G.
        fusion_dim: width of the fused features Z (1x1 convolution of [G; A]).
        readout_channels: channels each head reduces Z to before flattening its grid.
        head_hidden_dim: hidden width of the MANO and 2D heads' MLPs.
        appearance: the appearance ViT (WiLoR names).

    """

    crop_size: int = 256
    box_expansion: float = 1.5
    default_crop_extent_m: float = 0.25
    min_cam_scale: float = 0.1
    adapter_dim: int = 512
    fusion_dim: int = 1024
    readout_channels: int = 64
    head_hidden_dim: int = 1024
    appearance: AppearanceViTConfig = field(default_factory=AppearanceViTConfig)

    def __post_init__(self) -> None:
        """Reject non-positive sizes and a ViT input larger than the crop (ConfigError)."""
        require_positive(CONFIG_SECTION, crop_size=self.crop_size,
                         box_expansion=self.box_expansion,
                         default_crop_extent_m=self.default_crop_extent_m,
                         min_cam_scale=self.min_cam_scale, adapter_dim=self.adapter_dim,
                         fusion_dim=self.fusion_dim, readout_channels=self.readout_channels,
                         head_hidden_dim=self.head_hidden_dim)
        vit = self.appearance
        margins = (self.crop_size - vit.image_height, self.crop_size - vit.image_width)
        if min(margins) < 0 or margins[0] % 2 or margins[1] % 2:
            raise ConfigError(
                f'{CONFIG_SECTION}: the appearance input {vit.image_height}x{vit.image_width} '
                f'must fit centred in the {self.crop_size}-px crop (equal margins); change '
                'crop_size or appearance.image_height/image_width')

    @property
    def appearance_offset(self) -> tuple[int, int]:
        """Return (row, column) of the appearance input's top-left pixel inside the crop."""
        return ((self.crop_size - self.appearance.image_height) // 2,
                (self.crop_size - self.appearance.image_width) // 2)


def load_hand_branch_config(name_or_path: str | Path) -> HandBranchConfig:
    """Load a hand-branch configuration by name ('paper', 'tiny') or from a YAML path.

    Raises:
        ConfigError: for an unknown name, a missing file, unknown keys or wrong values.

    """
    text = str(name_or_path)
    if text in CONFIG_NAMES:
        path = config_dir() / f'hand_branch_{text}.yaml'
    elif text.endswith(('.yaml', '.yml')):
        path = Path(text)
    else:
        raise ConfigError(f'hand branch config {text!r}: use one of {list(CONFIG_NAMES)} or a '
                          'path to a .yaml file')
    return load_config(path, CONFIG_SECTION, HandBranchConfig)
