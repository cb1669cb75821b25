"""Rotary position embeddings: 2D (frame blocks) and 3D video RoPE (global blocks).

A ``Rotary`` holds per-token angles and rotates query/key features in place of their position.
Two pairings are used, as in LingBot-Map: the 2D RoPE splits the head dimension into a y half and
an x half and pairs feature ``i`` with ``i + d/4`` inside each half; the 3D RoPE pairs adjacent
features ``(2i, 2i + 1)`` and splits the pairs into time / height / width parts.

Token positions: special token ``k`` of a frame sits at 2D position (0, 0) and at 3D position
(t, k, k); patch (y, x) sits at (y + 1, x + 1) in 2D and at (t, n_special + y, n_special + x) in
3D, where ``t`` is the frame's time index (frames stored in memory before it).
"""

from dataclasses import dataclass

import torch


def _inverse_frequencies(dim: int, base: float, device: torch.device) -> torch.Tensor:
    """Return the ``dim // 2`` inverse frequencies ``base ** (-2i / dim)`` (float64)."""
    exponents = torch.arange(0, dim, 2, dtype=torch.float64, device=device)[:dim // 2] / dim
    return base ** -exponents


@dataclass(frozen=True)
class Rotary:
    """Rotation angles for N tokens.

    Attributes:
        cos: (N, D/2) float32 cosines, one per feature pair.
        sin: (N, D/2) float32 sines.
        interleaved: True pairs features (2i, 2i+1); False pairs (i, i + D/4) inside each half.

    """

    cos: torch.Tensor
    sin: torch.Tensor
    interleaved: bool

    def apply(self, x: torch.Tensor) -> torch.Tensor:
        """Rotate ``x`` (B, heads, N, D); the result keeps ``x``'s dtype."""
        cos = self.cos.to(x.dtype)
        sin = self.sin.to(x.dtype)
        if self.interleaved:
            pairs = x.unflatten(-1, (-1, 2))
            real, imag = pairs[..., 0], pairs[..., 1]
            return torch.stack((real * cos - imag * sin, real * sin + imag * cos),
                               dim=-1).flatten(-2)
        quarter = x.shape[-1] // 4
        first = torch.cat((x[..., :quarter], x[..., 2 * quarter:3 * quarter]), dim=-1)
        second = torch.cat((x[..., quarter:2 * quarter], x[..., 3 * quarter:]), dim=-1)
        new_first = first * cos - second * sin
        new_second = second * cos + first * sin
        return torch.cat((new_first[..., :quarter], new_second[..., :quarter],
                          new_first[..., quarter:], new_second[..., quarter:]), dim=-1)

    def repeat(self, times: int) -> 'Rotary':
        """Return the angles tiled ``times`` along the token axis (same grid, more frames)."""
        return Rotary(self.cos.repeat(times, 1), self.sin.repeat(times, 1), self.interleaved)


def frame_positions(grid: tuple[int, int], num_special: int,
                    device: torch.device) -> torch.Tensor:
    """Return the 2D positions (P, 2) = (y, x) of one frame's tokens: specials then patches."""
    height, width = grid
    ys, xs = torch.meshgrid(torch.arange(height, device=device),
                            torch.arange(width, device=device), indexing='ij')
    patches = torch.stack((ys.flatten(), xs.flatten()), dim=-1) + 1
    specials = torch.zeros(num_special, 2, dtype=patches.dtype, device=device)
    return torch.cat((specials, patches), dim=0)


def rotary_2d(positions: torch.Tensor, head_dim: int, frequency: float) -> Rotary:
    """Return the 2D RoPE angles for ``positions`` (N, 2) = (y, x) and a ``head_dim`` head."""
    inverse = _inverse_frequencies(head_dim // 2, frequency, positions.device)
    angles_y = positions[:, 0, None].double() * inverse
    angles_x = positions[:, 1, None].double() * inverse
    angles = torch.cat((angles_y, angles_x), dim=-1)
    return Rotary(angles.cos().float(), angles.sin().float(), interleaved=False)


def video_positions(grid: tuple[int, int], num_special: int, time_index: torch.Tensor
                    ) -> torch.Tensor:
    """Return the 3D positions (S * P, 3) = (t, h, w) of S frames' tokens, frame-major.

    Args:
        grid: patch grid (Hp, Wp).
        num_special: special tokens before the patches of each frame.
        time_index: (S,) integer time index of each frame.

    """
    device = time_index.device
    height, width = grid
    special = torch.arange(num_special, device=device)
    ys, xs = torch.meshgrid(torch.arange(height, device=device) + num_special,
                            torch.arange(width, device=device) + num_special, indexing='ij')
    spatial = torch.cat((torch.stack((special, special), dim=-1),
                         torch.stack((ys.flatten(), xs.flatten()), dim=-1)), dim=0)
    tokens = spatial.shape[0]
    times = time_index.to(device).repeat_interleave(tokens)[:, None]
    return torch.cat((times, spatial.repeat(time_index.numel(), 1)), dim=-1)


def rotary_3d(positions: torch.Tensor, split: tuple[int, int, int], theta: float) -> Rotary:
    """Return the 3D video RoPE angles for ``positions`` (N, 3) = (t, h, w).

    Args:
        positions: integer positions per token.
        split: head-dimension parts for time, height and width (even, summing to the head dim).
        theta: frequency base.

    """
    device = positions.device
    angles = [positions[:, axis, None].double() * _inverse_frequencies(part, theta, device)
              for axis, part in enumerate(split)]
    angles = torch.cat(angles, dim=-1)
    return Rotary(angles.cos().float(), angles.sin().float(), interleaved=True)
