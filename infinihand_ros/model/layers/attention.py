"""Multi-head self-attention with optional qk-norm and RoPE, on scaled-dot-product attention.

Key names mirror VGGT/LingBot-Map: ``qkv``, ``q_norm``, ``k_norm`` (LayerNorm over the head
dimension, only with qk-norm) and ``proj``. Attention over cached keys (streaming memory) is
delegated to an ``AttentionContext`` given by the caller, so this module holds no state.
"""

from typing import Protocol

from infinihand_ros.model.layers.rope import Rotary
import torch
from torch import nn
import torch.nn.functional as F


class AttentionContext(Protocol):
    """Attends the current tokens' queries to cached keys/values plus their own."""

    def attend(self, query: torch.Tensor, key: torch.Tensor, value: torch.Tensor
               ) -> torch.Tensor:
        """Return the attention output (B, heads, N, D) for the current (B, heads, N, D) q/k/v."""


class Attention(nn.Module):
    """Self-attention over (B, N, C) tokens; heads, widths and biases come from the caller."""

    def __init__(self, dim: int, num_heads: int, qkv_bias: bool = True, proj_bias: bool = True,
                 qk_norm: bool = False) -> None:
        """Build the projections; ``dim`` must be divisible by ``num_heads``."""
        super().__init__()
        if dim % num_heads:
            raise ValueError(f'attention dim {dim} is not divisible by num_heads {num_heads}')
        self.num_heads = num_heads
        head_dim = dim // num_heads
        self.qkv = nn.Linear(dim, 3 * dim, bias=qkv_bias)
        self.q_norm = nn.LayerNorm(head_dim) if qk_norm else nn.Identity()
        self.k_norm = nn.LayerNorm(head_dim) if qk_norm else nn.Identity()
        self.proj = nn.Linear(dim, dim, bias=proj_bias)

    def forward(self, x: torch.Tensor, rope: Rotary | None = None,
                context: AttentionContext | None = None) -> torch.Tensor:
        """Return the attended tokens (B, N, C).

        Args:
            x: (B, N, C) tokens.
            rope: rotary angles for the N tokens, or None for no positional rotation.
            context: cache-aware attention (keys stored after qk-norm and RoPE), or None for
                plain bidirectional attention among the N tokens.

        """
        batch, tokens, channels = x.shape
        qkv = self.qkv(x).unflatten(-1, (3, self.num_heads, -1)).permute(2, 0, 3, 1, 4)
        query, key, value = qkv.unbind(0)
        query, key = self.q_norm(query), self.k_norm(key)
        if rope is not None:
            query, key = rope.apply(query), rope.apply(key)
        # LayerNorm runs in fp32 under autocast; SDPA needs one dtype.
        query, key = query.to(value.dtype), key.to(value.dtype)
        if context is None:
            out = F.scaled_dot_product_attention(query, key, value)
        else:
            out = context.attend(query, key, value)
        return self.proj(out.transpose(1, 2).reshape(batch, tokens, channels))
