"""Pre-norm transformer block with LayerScale, and its MLP (names as in VGGT/DINOv2).

A block computes ``x + ls1(attn(norm1(x))) + ...``: keys ``norm1``, ``attn.*``, ``ls1.gamma``,
``norm2``, ``mlp.fc1``, ``mlp.fc2``, ``ls2.gamma``.
"""

from infinihand_ros.model.layers.attention import Attention
from infinihand_ros.model.layers.attention import AttentionContext
from infinihand_ros.model.layers.rope import Rotary
import torch
from torch import nn


class Mlp(nn.Module):
    """Two linear layers with GELU between them."""

    def __init__(self, in_features: int, hidden_features: int, out_features: int,
                 bias: bool = True) -> None:
        """Build ``fc1`` (in -> hidden) and ``fc2`` (hidden -> out)."""
        super().__init__()
        self.fc1 = nn.Linear(in_features, hidden_features, bias=bias)
        self.act = nn.GELU()
        self.fc2 = nn.Linear(hidden_features, out_features, bias=bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Return fc2(gelu(fc1(x))) over the last dimension."""
        return self.fc2(self.act(self.fc1(x)))


class LayerScale(nn.Module):
    """Per-channel learned scale ``gamma`` (initialised to ``init_value``)."""

    def __init__(self, dim: int, init_value: float) -> None:
        """Build ``gamma`` of shape (dim,)."""
        super().__init__()
        self.gamma = nn.Parameter(torch.full((dim,), float(init_value)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Return ``x * gamma``."""
        return x * self.gamma


class Block(nn.Module):
    """Pre-norm attention + MLP block with LayerScale on both residual branches."""

    def __init__(self, dim: int, num_heads: int, mlp_ratio: float, layer_scale_init: float,
                 qk_norm: bool = False, norm_eps: float = 1e-5) -> None:
        """Build a block of width ``dim``; the MLP is ``int(dim * mlp_ratio)`` wide."""
        super().__init__()
        self.norm1 = nn.LayerNorm(dim, eps=norm_eps)
        self.attn = Attention(dim, num_heads, qk_norm=qk_norm)
        self.ls1 = LayerScale(dim, layer_scale_init)
        self.norm2 = nn.LayerNorm(dim, eps=norm_eps)
        self.mlp = Mlp(dim, int(dim * mlp_ratio), dim)
        self.ls2 = LayerScale(dim, layer_scale_init)

    def forward(self, x: torch.Tensor, rope: Rotary | None = None,
                context: AttentionContext | None = None) -> torch.Tensor:
        """Return the block output for (B, N, C) tokens (see ``Attention.forward``)."""
        x = x + self.ls1(self.attn(self.norm1(x), rope=rope, context=context))
        return x + self.ls2(self.mlp(self.norm2(x)))
