"""Left/right mirroring of hand points and rotations (the standard MANO flip).

A left hand is the mirror image of a right hand through the plane x = 0 of MANO's canonical frame,
``M = diag(-1, 1, 1)``. Points map as ``(x, y, z) -> (-x, y, z)``; a rotation ``R`` maps to
``M R M``, which for an axis-angle vector is ``(x, y, z) -> (x, -y, -z)`` (``det M = -1`` flips the
axis of the mirrored rotation). Every function is its own inverse and accepts either a numpy array
or a torch tensor, returning the same kind (torch results keep dtype, device and gradients).
"""

from typing import Final, TypeVar

from infinihand_ros.core.errors import InputError
import numpy as np
import torch

ArrayOrTensor = TypeVar('ArrayOrTensor', np.ndarray, torch.Tensor)

#: Per-axis signs of the point mirror ``M = diag(-1, 1, 1)``.
POINT_MIRROR_SIGNS: Final = (-1.0, 1.0, 1.0)
#: Per-axis signs that mirror an axis-angle vector (``det(M) * M``).
AXIS_ANGLE_MIRROR_SIGNS: Final = (1.0, -1.0, -1.0)


def _multiply_last_axis(value: ArrayOrTensor, signs: np.ndarray, name: str,
                        trailing: tuple[int, ...]) -> ArrayOrTensor:
    """Multiply ``value`` by ``signs`` broadcast over its trailing axes after a shape check."""
    shape = tuple(value.shape) if isinstance(value, torch.Tensor) else np.shape(value)
    if len(shape) < len(trailing) or tuple(shape[-len(trailing):]) != trailing:
        raise InputError(f'{name}: expected shape (..., {", ".join(map(str, trailing))}), '
                         f'got {tuple(shape)}')
    if isinstance(value, torch.Tensor):
        return value * torch.as_tensor(signs, dtype=value.dtype, device=value.device)
    return np.asarray(value, dtype=np.float64) * signs


def mirror_points(points: ArrayOrTensor) -> ArrayOrTensor:
    """Mirror points (..., 3) through the plane x = 0: ``(x, y, z) -> (-x, y, z)``.

    Raises:
        InputError: if the last axis is not of size 3.

    """
    return _multiply_last_axis(points, np.asarray(POINT_MIRROR_SIGNS), 'points', (3,))


def mirror_axis_angle(axis_angle: ArrayOrTensor) -> ArrayOrTensor:
    """Mirror axis-angle rotations (..., 3): ``(x, y, z) -> (x, -y, -z)``, i.e. ``R -> M R M``.

    Raises:
        InputError: if the last axis is not of size 3.

    """
    return _multiply_last_axis(axis_angle, np.asarray(AXIS_ANGLE_MIRROR_SIGNS), 'axis_angle',
                               (3,))


def mirror_rotation_matrix(rotation: ArrayOrTensor) -> ArrayOrTensor:
    """Mirror rotation matrices (..., 3, 3): ``R -> M R M`` with ``M = diag(-1, 1, 1)``.

    Raises:
        InputError: if the trailing axes are not (3, 3).

    """
    signs = np.asarray(POINT_MIRROR_SIGNS)
    return _multiply_last_axis(rotation, np.outer(signs, signs), 'rotation', (3, 3))
