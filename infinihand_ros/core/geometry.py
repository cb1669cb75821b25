"""Numpy geometry: rotations (through scipy/roma), similarity alignment, pinhole projection, FoV.

Conventions: camera frame is OpenCV optical (x right, y down, z forward); quaternions are
(x, y, z, w); angles are radians; poses are camera-to-world.
"""

from typing import Final

import numpy as np
from scipy.spatial.transform import Rotation

#: Smallest depth (m) at which a point is projected (paper appendix A floors depth at 1 cm).
MIN_PROJECTION_DEPTH_M: Final = 0.01


def axis_angle_to_matrix(axis_angle: np.ndarray) -> np.ndarray:
    """Convert axis-angle vectors (..., 3), radians, to rotation matrices (..., 3, 3).

    The input is copied: scipy refuses read-only buffers (e.g. a frozen dataclass's arrays).
    """
    aa = np.array(axis_angle, dtype=np.float64)
    return Rotation.from_rotvec(aa.reshape(-1, 3)).as_matrix().reshape(aa.shape[:-1] + (3, 3))


def matrix_to_axis_angle(matrix: np.ndarray) -> np.ndarray:
    """Convert rotation matrices (..., 3, 3) to axis-angle vectors (..., 3), radians (copied)."""
    mat = np.array(matrix, dtype=np.float64)
    return Rotation.from_matrix(mat.reshape(-1, 3, 3)).as_rotvec().reshape(mat.shape[:-2] + (3,))


def quaternion_xyzw_to_matrix(quaternion_xyzw: np.ndarray) -> np.ndarray:
    """Convert (x, y, z, w) quaternions (..., 4) to rotation matrices (..., 3, 3)."""
    q = np.asarray(quaternion_xyzw, dtype=np.float64)
    return Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(q.shape[:-1] + (3, 3))


def matrix_to_quaternion_xyzw(matrix: np.ndarray) -> np.ndarray:
    """Convert rotation matrices (..., 3, 3) to unit (x, y, z, w) quaternions with w >= 0."""
    mat = np.asarray(matrix, dtype=np.float64)
    quat = Rotation.from_matrix(mat.reshape(-1, 3, 3)).as_quat(canonical=True)
    return quat.reshape(mat.shape[:-2] + (4,))


def rotation_angle_deg(rotation_a: np.ndarray, rotation_b: np.ndarray) -> np.ndarray:
    """Geodesic angle between rotation matrices (..., 3, 3) in degrees (paper appendix A, GO).

    ``180/pi * arccos(clamp((tr(A^T B) - 1) / 2, -1, 1))``.
    """
    a = np.asarray(rotation_a, dtype=np.float64)
    b = np.asarray(rotation_b, dtype=np.float64)
    trace = np.einsum('...ij,...ij->...', a, b)
    return np.degrees(np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0)))


def similarity_transform(source: np.ndarray, target: np.ndarray,
                         with_scale: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fit the proper similarity (Umeyama) mapping ``source`` points onto ``target`` points.

    Minimises ``sum_i ||s R x_i + t - y_i||^2`` over s > 0, R in SO(3), t (batched over leading
    dimensions, through roma's Kabsch/Umeyama solver in float64).

    Args:
        source: points (..., N, 3).
        target: corresponding points (..., N, 3).
        with_scale: fit the scale s; otherwise s = 1 (rigid alignment).

    Returns:
        (scale (...,), rotation (..., 3, 3), translation (..., 3)).

    """
    import roma  # torch stays out of processes that never align (the BA process)
    import torch

    x = torch.as_tensor(np.asarray(source, dtype=np.float64))
    y = torch.as_tensor(np.asarray(target, dtype=np.float64))
    if with_scale:
        rot, trans, scale = roma.rigid_points_registration(x, y, compute_scaling=True)
    else:
        rot, trans = roma.rigid_points_registration(x, y)
        scale = torch.ones(rot.shape[:-2], dtype=rot.dtype)
    return scale.numpy(), rot.numpy(), trans.numpy()


def apply_similarity(points: np.ndarray, scale: np.ndarray, rotation: np.ndarray,
                     translation: np.ndarray) -> np.ndarray:
    """Apply ``s R x + t`` to points (..., N, 3) with parameters from ``similarity_transform``."""
    rotated = np.einsum('...ij,...nj->...ni', rotation, points)
    return np.asarray(scale)[..., None, None] * rotated + np.asarray(translation)[..., None, :]


def align_similarity(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Return ``source`` (..., N, 3) after its best similarity alignment onto ``target``."""
    scale, rotation, translation = similarity_transform(source, target)
    return apply_similarity(source, scale, rotation, translation)


def project_points(points_cam: np.ndarray, intrinsics_matrix: np.ndarray,
                   min_depth_m: float = MIN_PROJECTION_DEPTH_M) -> np.ndarray:
    """Project camera-frame points (..., 3) in metres to pixels (..., 2) with a pinhole K.

    Depth is floored at ``min_depth_m`` so points behind the camera stay finite.

    Args:
        points_cam: points in the OpenCV optical frame, metres.
        intrinsics_matrix: 3x3 K, or (..., 3, 3) broadcastable to the points' leading dims.
        min_depth_m: depth floor used for the division.

    """
    pts = np.asarray(points_cam, dtype=np.float64)
    k = np.asarray(intrinsics_matrix, dtype=np.float64)
    depth = np.maximum(pts[..., 2:3], min_depth_m)
    normalized = pts[..., :2] / depth
    fx, fy = k[..., 0, 0], k[..., 1, 1]
    cx, cy = k[..., 0, 2], k[..., 1, 2]
    extra = normalized.ndim - 1 - np.ndim(fx)
    expand = (Ellipsis,) + (None,) * extra
    u = fx[expand] * normalized[..., 0] + cx[expand]
    v = fy[expand] * normalized[..., 1] + cy[expand]
    return np.stack([u, v], axis=-1)


def focal_from_fov(fov_rad: float | np.ndarray, size_px: float | np.ndarray) -> np.ndarray:
    """Focal length in pixels from a full field of view: ``f = (size/2) / tan(fov/2)``."""
    return (np.asarray(size_px, dtype=np.float64) / 2.0) / np.tan(np.asarray(fov_rad) / 2.0)


def fov_from_focal(focal_px: float | np.ndarray, size_px: float | np.ndarray) -> np.ndarray:
    """Full field of view in radians from a focal length: ``fov = 2 atan((size/2) / f)``."""
    return 2.0 * np.arctan((np.asarray(size_px, dtype=np.float64) / 2.0) / np.asarray(focal_px))


def transform_points(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply 4x4 rigid transforms (..., 4, 4) to points (..., N, 3)."""
    t = np.asarray(transform, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)
    return np.einsum('...ij,...nj->...ni', t[..., :3, :3], p) + t[..., None, :3, 3]


def make_transform(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Build 4x4 transforms (..., 4, 4) from rotations (..., 3, 3) and translations (..., 3)."""
    rot = np.asarray(rotation, dtype=np.float64)
    out = np.zeros(rot.shape[:-2] + (4, 4))
    out[..., :3, :3] = rot
    out[..., :3, 3] = translation
    out[..., 3, 3] = 1.0
    return out


def invert_transform(transform: np.ndarray) -> np.ndarray:
    """Invert rigid 4x4 transforms (..., 4, 4)."""
    t = np.asarray(transform, dtype=np.float64)
    rot_t = np.swapaxes(t[..., :3, :3], -1, -2)
    return make_transform(rot_t, -np.einsum('...ij,...j->...i', rot_t, t[..., :3, 3]))


def interpolate_transform(start: np.ndarray, end: np.ndarray, fraction: float) -> np.ndarray:
    """Rigid 4x4 transform ``fraction`` of the way from ``start`` to ``end``.

    The rotation turns about the relative rotation's axis (geodesic), the translation moves on
    the straight line; a fraction outside [0, 1] extrapolates.
    """
    a = np.asarray(start, dtype=np.float64)
    b = np.asarray(end, dtype=np.float64)
    relative = Rotation.from_matrix(a[:3, :3].T @ b[:3, :3]).as_rotvec()
    rotation = a[:3, :3] @ Rotation.from_rotvec(fraction * relative).as_matrix()
    return make_transform(rotation, a[:3, 3] + fraction * (b[:3, 3] - a[:3, 3]))
