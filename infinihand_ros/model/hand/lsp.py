"""Least-squares projection (LSP, paper eq. 5): the hand's lateral translation in closed form.

With the root depth ``t_z`` fixed, joint j of the translation-free hand ``X_j`` sits at depth
``z_j = X_j,z + t_z`` whatever ``(a, b)`` is, so its projection
``u_j = f_x (X_j,x + a) / z_j + c_x`` is affine in ``a`` (and ``v_j`` in ``b``). The pixel
error of eq. 5 is therefore a separable linear least-squares problem with the exact minimiser

    a = sum_j w_j g_j (p_j,u - c_x - f_x X_j,x / z_j) / sum_j w_j g_j^2,   g_j = f_x / z_j,

and the same for ``b`` with ``f_y``, ``c_y``. Joints with ``z_j`` below ``min_depth_m`` are left
out (the paper's valid set, positive depth); a hand with no valid joint gets ``a = b = 0``.
Everything is differentiable in every input.
"""

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import MIN_PROJECTION_DEPTH_M
import torch

#: Smallest normal-equation denominator (px^2/m^2 scale) treated as "no valid joint".
_MIN_DENOMINATOR = 1e-12


def _check_inputs(joints: torch.Tensor, landmarks_px: torch.Tensor, depth: torch.Tensor,
                  intrinsics: torch.Tensor, weights: torch.Tensor | None) -> None:
    """Raise InputError unless the LSP inputs have matching (N, J, ...) shapes."""
    if joints.ndim != 3 or joints.shape[-1] != 3:
        raise InputError(f'LSP joints: expected shape (N, J, 3), got {tuple(joints.shape)}')
    n, j = joints.shape[:2]
    expected = {'landmarks_px': (landmarks_px, (n, j, 2)), 'depth': (depth, (n,)),
                'intrinsics': (intrinsics, (n, 3, 3))}
    if weights is not None:
        expected['weights'] = (weights, (n, j))
    for name, (tensor, shape) in expected.items():
        if tuple(tensor.shape) != shape:
            raise InputError(f'LSP {name}: expected shape {shape} (N={n} hands, J={j} joints), '
                             f'got {tuple(tensor.shape)}')


def solve_lateral_translation(joints: torch.Tensor, landmarks_px: torch.Tensor,
                              depth: torch.Tensor, intrinsics: torch.Tensor,
                              weights: torch.Tensor | None = None,
                              min_depth_m: float = MIN_PROJECTION_DEPTH_M) -> torch.Tensor:
    """Solve eq. 5: the (t_x, t_y) that best aligns projected joints with 2D landmarks.

    Args:
        joints: (N, J, 3) translation-free joints in the camera frame of ``intrinsics``, metres.
        landmarks_px: (N, J, 2) target pixel positions (u, v) in that camera's image.
        depth: (N,) fixed translation depth t_z, metres.
        intrinsics: (N, 3, 3) pinhole K (zero skew) of that camera, pixels.
        weights: (N, J) non-negative per-joint weights; all ones if None.
        min_depth_m: joints with ``X_z + t_z`` below this depth are not used.

    Returns:
        (N, 2) translation (t_x, t_y) in metres; the full translation is (t_x, t_y, t_z).

    Raises:
        InputError: for inconsistent shapes.

    """
    _check_inputs(joints, landmarks_px, depth, intrinsics, weights)
    z = joints[..., 2] + depth[:, None]
    valid = z > min_depth_m
    weight = valid.to(joints.dtype)
    if weights is not None:
        weight = weight * weights
    safe_z = torch.where(valid, z, torch.ones_like(z))
    focal = torch.stack([intrinsics[:, 0, 0], intrinsics[:, 1, 1]], dim=-1)[:, None]
    centre = torch.stack([intrinsics[:, 0, 2], intrinsics[:, 1, 2]], dim=-1)[:, None]
    gain = focal / safe_z[..., None]
    residual_at_zero = landmarks_px - centre - gain * joints[..., :2]
    numerator = (weight[..., None] * gain * residual_at_zero).sum(dim=1)
    denominator = (weight[..., None] * gain * gain).sum(dim=1)
    solvable = denominator > _MIN_DENOMINATOR
    safe_denominator = torch.where(solvable, denominator, torch.ones_like(denominator))
    return torch.where(solvable, numerator / safe_denominator, torch.zeros_like(numerator))
