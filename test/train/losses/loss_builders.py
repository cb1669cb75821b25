"""Builders of the loss tests: rotations, rigid transforms and the empty-set check."""

import math

import torch


def rotation_x(angle: float) -> torch.Tensor:
    """Return the (3, 3) float64 rotation by ``angle`` radians about x."""
    c, s = math.cos(angle), math.sin(angle)
    return torch.tensor([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]], dtype=torch.float64)


def rotation_z(angle: float) -> torch.Tensor:
    """Return the (3, 3) float64 rotation by ``angle`` radians about z."""
    c, s = math.cos(angle), math.sin(angle)
    return torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=torch.float64)


def rigid(rotation: torch.Tensor, translation: tuple[float, float, float]) -> torch.Tensor:
    """Return the (4, 4) float64 transform [rotation | translation]."""
    transform = torch.eye(4, dtype=torch.float64)
    transform[:3, :3] = rotation
    transform[:3, 3] = torch.tensor(translation, dtype=torch.float64)
    return transform


def assert_zero_with_finite_grad(loss: torch.Tensor, *inputs: torch.Tensor) -> None:
    """Check ``loss`` is exactly 0 and backpropagates finite zero gradients into ``inputs``."""
    assert loss.item() == 0.0
    grads = torch.autograd.grad(loss, inputs, allow_unused=True)
    for grad in grads:
        if grad is not None:
            assert torch.isfinite(grad).all()
            assert torch.count_nonzero(grad) == 0
