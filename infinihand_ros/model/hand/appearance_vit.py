"""Appearance encoder: a ViTPose-style ViT on the RGB hand crop with WiLoR's module names.

The module tree and state-dict keys are WiLoR's ``backbone`` (``patch_embed.proj``, ``pos_embed``,
``blocks.N.{norm1, attn.qkv, attn.proj, norm2, mlp.fc1, mlp.fc2}``, ``last_norm``, the MANO query
embeddings ``pose_emb``/``shape_emb``/``cam_emb``, their decoders ``decpose``/``decshape``/
``deccam`` and the mean-parameter buffers ``init_hand_pose``/``init_betas``/``init_cam``), so a
WiLoR checkpoint's ``backbone.*`` entries load into it unchanged (paper configuration). As in
WiLoR, 16 pose tokens (mean 6D rotations of the wrist and 15 joints), one shape token and one
camera token are prepended to the image tokens; after the last block they decode, as residuals on
the means, into a coarse hand (6D pose, betas, weak-perspective camera ``[s, t_x, t_y]`` of the
square crop) that the hand branch refines. Facts from MODEL_ANCHORS.md section 4; written here.
"""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.model.hand.config import AppearanceViTConfig
import torch
from torch import nn
import torch.nn.functional as F

#: ImageNet normalisation applied to the [0, 1] RGB crop (as WiLoR's preprocessing).
IMAGENET_MEAN: Final = (0.485, 0.456, 0.406)
IMAGENET_STD: Final = (0.229, 0.224, 0.225)
#: Numbers of a 6D rotation: the first two columns of the matrix, ``[col1(3), col2(3)]``.
ROTATION_6D: Final = 6
#: Pose tokens: the global orientation and the 15 articulated joints.
NUM_POSE_TOKENS: Final = NUM_HAND_POSE_JOINTS + 1
#: Weak-perspective camera numbers ``[s, t_x, t_y]``.
CAM_DIM: Final = 3
#: The identity rotation in the 6D layout.
IDENTITY_6D: Final = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)
#: Standard deviation of the truncated-normal initialisation of weights and positions.
_INIT_STD: Final = 0.02
#: Gain of the decoders' Xavier initialisation, so the coarse hand starts at the mean.
_DECODER_GAIN: Final = 0.01


@dataclass(frozen=True)
class AppearanceOutput:
    """What the appearance encoder returns for N crops.

    Attributes:
        features: (N, D, Gh, Gw) image-token features A on the patch grid.
        pose_6d: (N, 16, 6) coarse 6D rotations, wrist (global orientation) first.
        betas: (N, 10) coarse shape.
        cam: (N, 3) coarse weak-perspective camera ``[s, t_x, t_y]`` of the square crop.

    """

    features: torch.Tensor
    pose_6d: torch.Tensor
    betas: torch.Tensor
    cam: torch.Tensor


class PatchEmbed(nn.Module):
    """Padded convolutional patch embedding (ViTPose): ``proj`` maps 3 -> D channels."""

    def __init__(self, config: AppearanceViTConfig) -> None:
        """Build the convolution (kernel = stride = patch, padding ``patch_padding``)."""
        super().__init__()
        self.proj = nn.Conv2d(3, config.embed_dim, kernel_size=config.patch_size,
                              stride=config.patch_size, padding=config.patch_padding)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """Return tokens (N, Gh * Gw, D) of normalised images (N, 3, h, w), row-major."""
        return self.proj(images).flatten(2).transpose(1, 2)


class Attention(nn.Module):
    """Multi-head self-attention with a fused ``qkv`` projection and ``proj`` output."""

    def __init__(self, config: AppearanceViTConfig) -> None:
        """Build the projections."""
        super().__init__()
        self.num_heads = config.num_heads
        self.qkv = nn.Linear(config.embed_dim, 3 * config.embed_dim, bias=config.qkv_bias)
        self.proj = nn.Linear(config.embed_dim, config.embed_dim)

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        """Attend over tokens (N, T, D)."""
        n, t, d = tokens.shape
        heads = self.num_heads
        q, k, v = self.qkv(tokens).view(n, t, 3, heads, d // heads).permute(2, 0, 3, 1, 4)
        attended = F.scaled_dot_product_attention(q, k, v)
        return self.proj(attended.transpose(1, 2).reshape(n, t, d))


class Mlp(nn.Module):
    """Two-layer GELU MLP (``fc1``, ``fc2``)."""

    def __init__(self, config: AppearanceViTConfig) -> None:
        """Build the layers (hidden width ``mlp_ratio * embed_dim``)."""
        super().__init__()
        hidden = int(config.embed_dim * config.mlp_ratio)
        self.fc1 = nn.Linear(config.embed_dim, hidden)
        self.fc2 = nn.Linear(hidden, config.embed_dim)

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        """Apply the MLP to tokens (N, T, D)."""
        return self.fc2(F.gelu(self.fc1(tokens)))


class Block(nn.Module):
    """Pre-norm transformer block (no LayerScale, as ViTPose)."""

    def __init__(self, config: AppearanceViTConfig) -> None:
        """Build norms, attention and MLP."""
        super().__init__()
        self.norm1 = nn.LayerNorm(config.embed_dim, eps=config.norm_eps)
        self.attn = Attention(config)
        self.norm2 = nn.LayerNorm(config.embed_dim, eps=config.norm_eps)
        self.mlp = Mlp(config)

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        """Apply the block to tokens (N, T, D)."""
        tokens = tokens + self.attn(self.norm1(tokens))
        return tokens + self.mlp(self.norm2(tokens))


class AppearanceViT(nn.Module):
    """WiLoR's ViT backbone on the central (h, w) of the canonical RGB crop."""

    def __init__(self, config: AppearanceViTConfig, default_cam_scale: float) -> None:
        """Build the ViT; the mean buffers start at the identity pose, zero betas and a camera.

        Args:
            config: sizes.
            default_cam_scale: weak-perspective scale ``s`` of the ``init_cam`` buffer (a WiLoR
                checkpoint replaces all three mean buffers).

        """
        super().__init__()
        self.config = config
        dim = config.embed_dim
        grid_h, grid_w = config.grid_size
        # Registration order reproduces WiLoR's state-dict order.
        self.patch_embed = PatchEmbed(config)
        self.register_buffer('init_cam', torch.tensor([[default_cam_scale, 0.0, 0.0]]))
        self.register_buffer('init_hand_pose', torch.tensor([IDENTITY_6D * NUM_POSE_TOKENS]))
        self.register_buffer('init_betas', torch.zeros(1, NUM_BETAS))
        self.pose_emb = nn.Linear(ROTATION_6D, dim)
        self.shape_emb = nn.Linear(NUM_BETAS, dim)
        self.cam_emb = nn.Linear(CAM_DIM, dim)
        self.decpose = nn.Linear(dim, ROTATION_6D)
        self.decshape = nn.Linear(dim, NUM_BETAS)
        self.deccam = nn.Linear(dim, CAM_DIM)
        # Slot 0 is ViTPose's class-token position; WiLoR adds it to every image token.
        self.pos_embed = nn.Parameter(torch.zeros(1, grid_h * grid_w + 1, dim))
        self.blocks = nn.ModuleList(Block(config) for _ in range(config.depth))
        self.last_norm = nn.LayerNorm(dim, eps=config.norm_eps)
        self.register_buffer('_mean', torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1),
                             persistent=False)
        self.register_buffer('_std', torch.tensor(IMAGENET_STD).view(1, 3, 1, 1),
                             persistent=False)
        self._init_weights()

    def _init_weights(self) -> None:
        """Truncated-normal weights and positions, zero biases, near-zero decoders."""
        for module in self.modules():
            if isinstance(module, nn.Linear):
                nn.init.trunc_normal_(module.weight, std=_INIT_STD)
                nn.init.zeros_(module.bias)
        nn.init.trunc_normal_(self.pos_embed, std=_INIT_STD)
        for decoder in (self.decpose, self.decshape, self.deccam):
            nn.init.xavier_uniform_(decoder.weight, gain=_DECODER_GAIN)

    def _query_tokens(self, batch: int) -> torch.Tensor:
        """Return the (N, 18, D) pose, shape and camera tokens embedded from the means."""
        pose = self.pose_emb(self.init_hand_pose.view(1, NUM_POSE_TOKENS, ROTATION_6D))
        shape = self.shape_emb(self.init_betas)[:, None]
        cam = self.cam_emb(self.init_cam)[:, None]
        return torch.cat([pose, shape, cam], dim=1).expand(batch, -1, -1)

    def forward(self, images: torch.Tensor) -> AppearanceOutput:
        """Encode RGB crops.

        Args:
            images: (N, 3, h, w) RGB in [0, 1], the central (h, w) of the canonical crops.

        Returns:
            Image features on the (h / patch, w / patch) grid and the coarse hand.

        Raises:
            InputError: for an image size other than the configured one.

        """
        expected = (3, self.config.image_height, self.config.image_width)
        if images.ndim != 4 or tuple(images.shape[1:]) != expected:
            raise InputError(f'appearance ViT input: expected (N, {", ".join(map(str, expected))})'
                             f' RGB crops, got {tuple(images.shape)}')
        n = images.shape[0]
        patches = self.patch_embed((images - self._mean) / self._std)
        patches = patches + self.pos_embed[:, 1:] + self.pos_embed[:, :1]
        num_queries = NUM_POSE_TOKENS + 2
        tokens = torch.cat([self._query_tokens(n), patches], dim=1)
        for block in self.blocks:
            tokens = block(tokens)
        tokens = self.last_norm(tokens)
        pose_6d = self.decpose(tokens[:, :NUM_POSE_TOKENS]) + self.init_hand_pose.view(
            1, NUM_POSE_TOKENS, ROTATION_6D)
        betas = self.decshape(tokens[:, NUM_POSE_TOKENS]) + self.init_betas
        cam = self.deccam(tokens[:, NUM_POSE_TOKENS + 1]) + self.init_cam
        grid_h, grid_w = self.config.grid_size
        features = tokens[:, num_queries:].transpose(1, 2).reshape(
            n, self.config.embed_dim, grid_h, grid_w)
        return AppearanceOutput(features=features, pose_6d=pose_6d, betas=betas, cam=cam)
