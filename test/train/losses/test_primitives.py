"""Tests of train/losses/primitives.py: masked mean, rho_eps, d_SO(3), shape checks."""

import math

from infinihand_ros.core.errors import InputError
from infinihand_ros.train.losses.primitives import check_mask
from infinihand_ros.train.losses.primitives import check_shape
from infinihand_ros.train.losses.primitives import consecutive_pairs
from infinihand_ros.train.losses.primitives import finite_or_zero
from infinihand_ros.train.losses.primitives import masked_mean
from infinihand_ros.train.losses.primitives import promote
from infinihand_ros.train.losses.primitives import smooth_l1
from infinihand_ros.train.losses.primitives import so3_distance
from loss_builders import rotation_x
from loss_builders import rotation_z
import pytest
import torch


def test_masked_mean_averages_the_valid_entries_only() -> None:
    """(1 + 3) / 2 with the other entries, infinite or not, ignored."""
    values = torch.tensor([1.0, 2.0, 3.0, float('inf')])
    valid = torch.tensor([True, False, True, False])
    assert masked_mean(values, valid).item() == 2.0


def test_masked_mean_of_an_empty_set_is_exactly_zero_with_zero_gradient() -> None:
    """No valid entry: the result is 0.0, connected to the input, and its gradient is 0."""
    values = torch.tensor([1.0, -2.0], requires_grad=True)
    loss = masked_mean(values * 3.0, torch.zeros(2, dtype=torch.bool))
    assert loss.item() == 0.0
    loss.backward()
    assert values.grad.tolist() == [0.0, 0.0]


def test_smooth_l1_matches_the_paper_on_both_sides_of_eps() -> None:
    """rho_0.5: 0.2 -> 0.04 / 1 = 0.04; -2 -> 2 - 0.25; continuous at |r| = eps."""
    residual = torch.tensor([0.2, -2.0, 0.5, 0.0], dtype=torch.float64)
    torch.testing.assert_close(smooth_l1(residual, 0.5),
                               torch.tensor([0.04, 1.75, 0.25, 0.0], dtype=torch.float64))
    below = smooth_l1(torch.tensor(0.5 - 1e-9, dtype=torch.float64), 0.5)
    assert below.item() == pytest.approx(0.25, abs=1e-8)


def test_so3_distance_of_known_rotations() -> None:
    """Same axis: |0.3 - (-0.2)|; identical: arccos(1 - eps); half turn: arccos(-1 + eps)."""
    eps = 1e-6
    distance = so3_distance(rotation_z(0.3), rotation_z(-0.2), eps)
    assert distance.item() == pytest.approx(0.5, abs=1e-12)
    same = so3_distance(rotation_x(0.7), rotation_x(0.7), eps)
    assert same.item() == pytest.approx(math.acos(1.0 - eps), abs=1e-9)
    half = so3_distance(rotation_x(math.pi), torch.eye(3, dtype=torch.float64), eps)
    assert half.item() == pytest.approx(math.acos(-1.0 + eps), abs=1e-9)


def test_so3_distance_gradient_is_finite_at_the_clamp() -> None:
    """Identical and opposite rotations give finite (zero) gradients, not NaN."""
    pred = torch.stack([torch.eye(3, dtype=torch.float64), rotation_x(math.pi)])
    pred.requires_grad_(True)
    so3_distance(pred, torch.eye(3, dtype=torch.float64).expand(2, 3, 3), 1e-6).sum().backward()
    assert torch.isfinite(pred.grad).all()


def test_so3_distance_gradcheck() -> None:
    """The d_SO(3) gradient matches finite differences away from the clamp (float64)."""
    target = rotation_x(0.4) @ rotation_z(1.1)
    pred = (rotation_z(0.2) @ rotation_x(-0.5)).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda r: so3_distance(r, target, 1e-6), (pred,))


def test_finite_or_zero_and_promote() -> None:
    """Non-finite entries become 0; half precision is computed in float32, float64 stays."""
    cleaned = finite_or_zero(torch.tensor([1.0, float('nan'), -float('inf')]))
    assert cleaned.tolist() == [1.0, 0.0, 0.0]
    half, single = promote(torch.zeros(1, dtype=torch.bfloat16), torch.zeros(1))
    assert half.dtype == single.dtype == torch.float32
    assert promote(torch.zeros(1), torch.zeros(1, dtype=torch.float64))[0].dtype == torch.float64


def test_checks_name_the_argument_and_the_shapes() -> None:
    """Shape and dtype errors say which input, what was expected and what came."""
    with pytest.raises(InputError, match=r'pred: expected shape \(\*, 21, 2\), got \(3, 20, 2\)'):
        check_shape('pred', torch.zeros(3, 20, 2), (None, 21, 2))
    with pytest.raises(InputError, match='valid: expected a bool validity mask, got dtype'):
        check_mask('valid', torch.ones(2), (2,))


def test_consecutive_pairs_needs_both_frames_and_the_adjacency_flag() -> None:
    """Pairs (t, t + 1) are valid when both frames are and ``consecutive`` allows it."""
    valid = torch.tensor([[True, True, True, False]])
    assert consecutive_pairs(valid, None).tolist() == [[True, True, False]]
    adjacency = torch.tensor([[True, False, True]])
    assert consecutive_pairs(valid, adjacency).tolist() == [[True, False, False]]
    per_hand = consecutive_pairs(valid[..., None].expand(1, 4, 2), adjacency)
    assert per_hand.shape == (1, 3, 2)
    with pytest.raises(InputError, match=r'consecutive: expected shape \(1, 3\)'):
        consecutive_pairs(valid, torch.ones(1, 4, dtype=torch.bool))
