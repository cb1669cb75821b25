"""Tests of model/layers/rope.py: norm preservation and relative-position dot products."""

from infinihand_ros.model.layers.rope import frame_positions
from infinihand_ros.model.layers.rope import rotary_2d
from infinihand_ros.model.layers.rope import rotary_3d
from infinihand_ros.model.layers.rope import video_positions
import pytest
import torch


def _rotary(kind: str, positions: torch.Tensor):
    if kind == '2d':
        return rotary_2d(positions, 16, 100.0)
    return rotary_3d(positions, (4, 6, 6), 10000.0)


@pytest.mark.parametrize('kind', ['2d', '3d'])
def test_rotation_preserves_norms(kind: str) -> None:
    """Rotary embedding is a rotation: feature norms are unchanged."""
    torch.manual_seed(0)
    positions = torch.randint(0, 30, (7, 2 if kind == '2d' else 3))
    x = torch.randn(1, 2, 7, 16)
    rotated = _rotary(kind, positions).apply(x)
    torch.testing.assert_close(rotated.norm(dim=-1), x.norm(dim=-1))


@pytest.mark.parametrize('kind', ['2d', '3d'])
def test_dot_product_depends_on_relative_position(kind: str) -> None:
    """<R(p) q, R(p') k> is unchanged when p and p' shift together."""
    torch.manual_seed(1)
    dims = 2 if kind == '2d' else 3
    query, key = torch.randn(1, 1, 1, 16), torch.randn(1, 1, 1, 16)
    p, p_prime = torch.tensor([[3] * dims]), torch.tensor([[7, 1, 5][:dims]])
    shift = torch.tensor([[4, 9, 2][:dims]])

    def score(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        return (_rotary(kind, a).apply(query) * _rotary(kind, b).apply(key)).sum()

    torch.testing.assert_close(score(p, p_prime), score(p + shift, p_prime + shift))
    assert not torch.allclose(score(p, p_prime), score(p, p_prime + shift))


def test_token_positions_follow_the_layout() -> None:
    """Specials sit at (0, 0) / (t, k, k); patch (y, x) at (y+1, x+1) / (t, 6+y, 6+x)."""
    positions = frame_positions((2, 3), 6, torch.device('cpu'))
    assert positions[:6].abs().sum() == 0
    assert positions[6 + 1 * 3 + 2].tolist() == [2, 3]
    video = video_positions((2, 3), 6, torch.tensor([5, 9]))
    assert video.shape == (2 * 12, 3)
    assert video[2].tolist() == [5, 2, 2]
    assert video[12 + 6 + 1 * 3 + 2].tolist() == [9, 7, 8]
