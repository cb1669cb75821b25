"""Building blocks shared by the loss terms: masked means, rho_eps, d_SO(3) and input checks.

Every loss of appendix B averages over a valid set and is exactly zero when that set is empty.
``masked_mean`` gives that, and keeps a finite gradient path as long as the values it masks out
are finite: so targets are passed through ``finite_or_zero`` (a NaN target behind a False flag
would otherwise turn the zero gradient into NaN) and every division or arccos is guarded.
Inputs in half precision (bf16 autocast) are computed in float32.
"""

from collections.abc import Sequence

from infinihand_ros.core.errors import InputError
import torch


def promote(*tensors: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """Return ``tensors`` as one floating dtype, at least float32 (float64 if any is)."""
    dtype = torch.float64 if any(t.dtype == torch.float64 for t in tensors) else torch.float32
    return tuple(t.to(dtype) for t in tensors)


def finite_or_zero(values: torch.Tensor) -> torch.Tensor:
    """Return ``values`` with NaN and infinite entries replaced by 0 (for masked-out targets)."""
    return torch.where(torch.isfinite(values), values, torch.zeros_like(values))


def finite_rows(values: torch.Tensor, dims: int = 1) -> torch.Tensor:
    """Return a bool mask of ``values.shape[:-dims]``: True where the last ``dims`` are finite."""
    finite = torch.isfinite(values)
    return finite.flatten(-dims).all(dim=-1)


def masked_mean(values: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Return the mean of ``values`` over the True entries of ``valid`` (pooled over the batch).

    Args:
        values: per-item errors, any shape; entries where ``valid`` is False must be finite.
        valid: bool mask of the same shape.

    Returns:
        A scalar: the sum over the valid set divided by its size, exactly 0 when it is empty
        (still connected to ``values`` so ``backward`` runs and gives zero gradients).

    """
    total = torch.where(valid, values, torch.zeros_like(values)).sum()
    return total / valid.sum().clamp(min=1).to(values.dtype)


def smooth_l1(residual: torch.Tensor, epsilon: float) -> torch.Tensor:
    """Return rho_eps(r) element-wise: r^2 / (2 eps) for |r| < eps, else |r| - eps / 2.

    Args:
        residual: any shape.
        epsilon: the width eps > 0 (same units as ``residual``).

    """
    magnitude = residual.abs()
    return torch.where(magnitude < epsilon, 0.5 * residual * residual / epsilon,
                       magnitude - 0.5 * epsilon)


def so3_distance(rotation_pred: torch.Tensor, rotation_target: torch.Tensor,
                 clamp_eps: float) -> torch.Tensor:
    """Return d_SO(3) (appendix B.3): arccos(clamp((tr(R_hat^T R) - 1) / 2, -1 + e, 1 - e)).

    Args:
        rotation_pred: (..., 3, 3) rotation matrices R_hat.
        rotation_target: (..., 3, 3) rotation matrices R.
        clamp_eps: e in (0, 1); the clamp bounds the gradient, and makes d(R, R) equal
            arccos(1 - e) instead of 0 (a constant, with zero gradient).

    Returns:
        (...) angles in radians.

    """
    trace = (rotation_pred * rotation_target).sum(dim=(-2, -1))
    cosine = ((trace - 1.0) / 2.0).clamp(-1.0 + clamp_eps, 1.0 - clamp_eps)
    return torch.arccos(cosine)


def check_shape(name: str, tensor: torch.Tensor, shape: Sequence[int | None]) -> None:
    """Raise InputError unless ``tensor`` has ``shape`` (``None`` entries match any size).

    Args:
        name: the argument named in the error.
        tensor: the tensor to check.
        shape: expected sizes, one per dimension.

    """
    got = tuple(tensor.shape)
    if len(got) != len(shape) or any(s is not None and s != g for s, g in zip(shape, got)):
        wanted = '(' + ', '.join('*' if s is None else str(s) for s in shape) + ')'
        raise InputError(f'{name}: expected shape {wanted}, got {got}; see the loss '
                         "function's docstring for the layout")


def check_mask(name: str, mask: torch.Tensor, shape: Sequence[int]) -> None:
    """Raise InputError unless ``mask`` is a bool tensor of exactly ``shape``."""
    if mask.dtype != torch.bool:
        raise InputError(f'{name}: expected a bool validity mask, got dtype {mask.dtype}; '
                         'pass a comparison or .bool() of the flags')
    check_shape(name, mask, tuple(shape))


def check_like(name: str, tensor: torch.Tensor, reference_name: str,
               reference: torch.Tensor) -> None:
    """Raise InputError unless ``tensor`` has the shape of ``reference`` (named in the error)."""
    if tensor.shape != reference.shape:
        raise InputError(f'{name}: expected the shape of {reference_name} '
                         f'{tuple(reference.shape)}, got {tuple(tensor.shape)}')


def consecutive_pairs(valid: torch.Tensor, consecutive: torch.Tensor | None) -> torch.Tensor:
    """Return the (B, S - 1, ...) mask of frame pairs (t, t + 1) that are both valid.

    Args:
        valid: (B, S, ...) bool per-frame validity.
        consecutive: (B, S - 1) bool, True where frame t + 1 directly follows frame t in time
            (e.g. False between the anchors and the first window when they are not adjacent);
            None when every neighbour in the clip is consecutive.

    Raises:
        InputError: for a ``consecutive`` mask of the wrong shape or dtype.

    """
    pairs = valid[:, 1:] & valid[:, :-1]
    if consecutive is None:
        return pairs
    check_mask('consecutive', consecutive, pairs.shape[:2])
    return pairs & consecutive.reshape(*consecutive.shape, *([1] * (pairs.ndim - 2)))
