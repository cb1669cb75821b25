"""Frozen configuration dataclasses of the geometry branch (section ``geometry:`` of a model YAML).

``config/model_paper.yaml`` reproduces LingBot-Map's sizes so its checkpoint loads by identity;
``config/model_tiny.yaml`` is the same code with small numbers for CPU, tests and the demo. Every
dimension of the network comes from here; head widths are derived from the aggregator's.
"""

from dataclasses import dataclass
from dataclasses import field
from pathlib import Path

from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import load_config
from infinihand_ros.core.config import require_positive
from infinihand_ros.model.pose_encoding import CAM_TO_WORLD
from infinihand_ros.model.pose_encoding import check_pose_direction

PATCH_EMBED_KINDS = ('conv', 'dinov2')
GLOBAL_ROPE_KINDS = ('video3d', 'spatial2d')
GEOMETRY_SECTION = 'geometry'
#: How frames are fitted to the model input (``GeometryConfig.preprocessing``; implemented in
#: ``engine/frame_input.py``): LingBot-Map/VGGT's resize-and-crop or resize-and-pad, or ours.
RESIZE_CROP = 'resize_crop'
RESIZE_PAD = 'resize_pad'
LETTERBOX = 'letterbox'
PREPROCESSING_MODES = (RESIZE_CROP, RESIZE_PAD, LETTERBOX)


@dataclass(frozen=True)
class PatchEmbedConfig:
    """Patch embedding: a plain conv (``conv``) or a DINOv2 ViT with registers (``dinov2``).

    ``depth``, ``num_heads``, ``num_register_tokens``, ``pretrain_image_size`` and
    ``layer_scale_init`` only apply to ``dinov2``; its positional table is stored for a square
    ``pretrain_image_size`` image and interpolated to the actual patch grid at run time.
    """

    kind: str = 'conv'
    depth: int = 0
    num_heads: int = 1
    mlp_ratio: float = 4.0
    num_register_tokens: int = 0
    pretrain_image_size: int = 518
    layer_scale_init: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in PATCH_EMBED_KINDS:
            raise ValueError(f'patch_embed.kind must be one of {PATCH_EMBED_KINDS}, '
                             f'got {self.kind!r}')
        if self.kind == 'dinov2':
            require_positive('patch_embed', depth=self.depth, num_heads=self.num_heads,
                             pretrain_image_size=self.pretrain_image_size)


@dataclass(frozen=True)
class AggregatorConfig:
    """Alternating-attention aggregator (frame blocks with 2D RoPE, global blocks with memory).

    ``rope3d_split`` splits the head dimension into time / height / width parts (even numbers
    summing to ``embed_dim // num_heads``). ``selected_layers`` are the alternating-attention
    outputs returned to the heads (the DPT heads read all four, the camera head the last).
    """

    image_height: int = 168
    image_width: int = 224
    patch_size: int = 14
    embed_dim: int = 192
    depth: int = 4
    num_heads: int = 3
    mlp_ratio: float = 4.0
    num_register_tokens: int = 4
    qk_norm: bool = True
    layer_scale_init: float = 0.01
    rope_frequency: float = 100.0
    global_rope: str = 'video3d'
    rope3d_theta: float = 10000.0
    rope3d_split: tuple[int, int, int] = (20, 22, 22)
    selected_layers: tuple[int, ...] = (0, 1, 2, 3)
    patch_embed: PatchEmbedConfig = field(default_factory=PatchEmbedConfig)

    def __post_init__(self) -> None:
        require_positive('aggregator', image_height=self.image_height,
                         image_width=self.image_width, patch_size=self.patch_size,
                         embed_dim=self.embed_dim, depth=self.depth, num_heads=self.num_heads)
        if self.image_height % self.patch_size or self.image_width % self.patch_size:
            raise ValueError(f'aggregator image size {self.image_height}x{self.image_width} '
                             f'must be a multiple of patch_size {self.patch_size}')
        if self.embed_dim % self.num_heads:
            raise ValueError(f'aggregator.embed_dim {self.embed_dim} must be divisible by '
                             f'num_heads {self.num_heads}')
        head_dim = self.embed_dim // self.num_heads
        if head_dim % 4:
            raise ValueError(f'aggregator head dim {head_dim} must be a multiple of 4 (2D RoPE)')
        if self.global_rope not in GLOBAL_ROPE_KINDS:
            raise ValueError(f'aggregator.global_rope must be one of {GLOBAL_ROPE_KINDS}, '
                             f'got {self.global_rope!r}')
        if sum(self.rope3d_split) != head_dim or any(part % 2 for part in self.rope3d_split):
            raise ValueError(f'aggregator.rope3d_split {self.rope3d_split} must be even numbers '
                             f'summing to the head dim {head_dim}')
        if len(self.selected_layers) != 4 or not all(
                0 <= index < self.depth for index in self.selected_layers):
            raise ValueError(f'aggregator.selected_layers must be 4 indices in [0, {self.depth}), '
                             f'got {self.selected_layers}')

    @property
    def patch_grid(self) -> tuple[int, int]:
        """Return the patch grid (Hp, Wp) of the configured image size."""
        return self.image_height // self.patch_size, self.image_width // self.patch_size

    @property
    def num_special_tokens(self) -> int:
        """Return the tokens before the patches of each frame: camera, registers, scale."""
        return 1 + self.num_register_tokens + 1

    @property
    def output_dim(self) -> int:
        """Return the width of an aggregated token: frame and global outputs concatenated."""
        return 2 * self.embed_dim


@dataclass(frozen=True)
class CameraHeadConfig:
    """Causal camera head: trunk of transformer blocks over camera tokens, iterative refinement."""

    trunk_depth: int = 1
    num_heads: int = 3
    mlp_ratio: float = 4.0
    num_iterations: int = 2
    layer_scale_init: float = 0.01

    def __post_init__(self) -> None:
        require_positive('camera_head', trunk_depth=self.trunk_depth, num_heads=self.num_heads,
                         num_iterations=self.num_iterations)


@dataclass(frozen=True)
class DptConfig:
    """DPT decoder sizes shared by the depth and the mask head (VGGT/LingBot-Map layout)."""

    features: int = 64
    out_channels: tuple[int, int, int, int] = (64, 128, 256, 256)
    head_features: int = 32
    pos_embed: bool = True

    def __post_init__(self) -> None:
        require_positive('dpt', features=self.features, head_features=self.head_features,
                         min_out_channels=min(self.out_channels))


@dataclass(frozen=True)
class MemoryConfig:
    """Geometric Context Attention memory: anchor frames, keyframe window, trajectory memory.

    ``max_trajectory_frames`` bounds the trajectory memory (and the camera head's cache) to the
    newest evicted keyframes, so memory stays flat over arbitrarily long streams (LingBot-Map
    sizes its cache for 1,024 frames).
    """

    anchor_frames: int = 2
    window: int = 8
    max_trajectory_frames: int = 1024

    def __post_init__(self) -> None:
        require_positive('memory', anchor_frames=self.anchor_frames,
                         max_trajectory_frames=self.max_trajectory_frames)
        if self.window < 0:
            raise ValueError(f'memory.window must be >= 0, got {self.window}')


@dataclass(frozen=True)
class MaskConfig:
    """Hand localisation: mask threshold and minimum area (paper Sec. 3.2).

    The box expansion (x1.5) is the hand branch's ``box_expansion``, not a mask setting.
    """

    threshold: float = 0.5
    min_pixels: int = 16

    def __post_init__(self) -> None:
        if not 0.0 < self.threshold < 1.0:
            raise ValueError(f'masks.threshold must be in (0, 1), got {self.threshold}')
        require_positive('masks', min_pixels=self.min_pixels)


@dataclass(frozen=True)
class GeometryConfig:
    """The whole geometry branch, and the two conventions its weights were trained with.

    Attributes:
        aggregator: backbone sizes (and the model input size, see ``preprocessing``).
        camera_head: camera head sizes.
        dpt: depth / mask decoder sizes.
        memory: streaming memory sizes.
        masks: hand-mask thresholds.
        autocast_bf16: run the aggregator in bf16 autocast (CUDA only).
        pose_direction: which way the camera head's ``[R | t]`` points, ``cam_to_world`` (ours,
            LingBot-Map) or ``world_to_cam`` (VGGT); see ``model/pose_encoding.py``.
        preprocessing: how frames are fitted to the input: ``letterbox`` (ours: scaled into
            ``image_width`` x ``image_height``, black bars), ``resize_crop`` (LingBot-Map/VGGT:
            width ``image_width``, bicubic, height rounded to the patch and centre-cropped to at
            most ``image_width``) or ``resize_pad`` (the longer side ``image_width``, padded
            white to a square); see ``engine/frame_input.py``.

    """

    aggregator: AggregatorConfig = field(default_factory=AggregatorConfig)
    camera_head: CameraHeadConfig = field(default_factory=CameraHeadConfig)
    dpt: DptConfig = field(default_factory=DptConfig)
    memory: MemoryConfig = field(default_factory=MemoryConfig)
    masks: MaskConfig = field(default_factory=MaskConfig)
    autocast_bf16: bool = True
    pose_direction: str = CAM_TO_WORLD
    preprocessing: str = LETTERBOX

    def __post_init__(self) -> None:
        check_pose_direction(self.pose_direction)
        if self.preprocessing not in PREPROCESSING_MODES:
            raise ValueError(f'preprocessing must be one of {list(PREPROCESSING_MODES)}, '
                             f'got {self.preprocessing!r}')


def load_geometry_config(path: str | Path, require_complete: bool = False) -> GeometryConfig:
    """Load the ``geometry:`` section of a model YAML file.

    Args:
        path: the YAML file.
        require_complete: every field must be in the file (checkpoint configs), instead of
            defaults filling in what is left out.

    Raises:
        ConfigError: for a missing file or section, an unknown key, a wrong type or a bad value,
            and with ``require_complete`` for a missing field.

    """
    return load_config(path, GEOMETRY_SECTION, GeometryConfig, require_complete=require_complete)


def named_config_path(name: str) -> Path:
    """Return ``config/model_<name>.yaml`` of the package (e.g. ``paper`` or ``tiny``)."""
    return config_dir() / f'model_{name}.yaml'
