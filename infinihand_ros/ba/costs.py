"""Residuals and Jacobians of the BA cost: reprojection, depth prior, relative-pose prior.

All functions are vectorised over observations, tracks and pose pairs. Poses are world-to-camera
``(R, t)``, perturbed on the left with twists ``(v, omega)`` (see ``ba.lie``); a track's point is
``X_host = ray / rho`` with ``ray = K_host^-1 [u, v, 1]``.
"""

from dataclasses import dataclass

from infinihand_ros.ba import lie
import numpy as np
from scipy.spatial.transform import Rotation


@dataclass(frozen=True)
class PoseState:
    """Current values of the BA variables.

    Attributes:
        rotation: (F, 3, 3) world-to-camera rotations.
        translation: (F, 3) world-to-camera translations (m).
        inv_depth: (P,) per-track inverse depths (1/m).

    """

    rotation: np.ndarray
    translation: np.ndarray
    inv_depth: np.ndarray


@dataclass(frozen=True)
class Reprojection:
    """Reprojection residuals (M, 2) in px and their Jacobians.

    Attributes:
        residual: (M, 2) projected minus observed pixel.
        jac_host: (M, 2, 6) w.r.t. the host pose's twist.
        jac_target: (M, 2, 6) w.r.t. the observing pose's twist.
        jac_inv_depth: (M, 2) w.r.t. the track's inverse depth.

    """

    residual: np.ndarray
    jac_host: np.ndarray
    jac_target: np.ndarray
    jac_inv_depth: np.ndarray


def host_rays(intrinsics: np.ndarray, host: np.ndarray, host_xy: np.ndarray) -> np.ndarray:
    """Return unit-depth rays (P, 3) ``K_host^-1 [u, v, 1]`` of the tracks' host pixels."""
    k = intrinsics[host]
    x = (host_xy[:, 0] - k[:, 0, 2]) / k[:, 0, 0]
    y = (host_xy[:, 1] - k[:, 1, 2]) / k[:, 1, 1]
    return np.stack([x, y, np.ones_like(x)], axis=-1)


def reprojection(state: PoseState, rays: np.ndarray, host: np.ndarray, obs_track: np.ndarray,
                 obs_frame: np.ndarray, obs_xy: np.ndarray, intrinsics: np.ndarray,
                 with_jacobians: bool = True) -> Reprojection:
    """Reproject every observation's track from its host into the observing keyframe.

    Args:
        state: current poses and inverse depths.
        rays: (P, 3) host rays from ``host_rays``.
        host: (P,) host keyframe per track.
        obs_track: (M,) track per observation.
        obs_frame: (M,) observing keyframe per observation.
        obs_xy: (M, 2) observed pixels.
        intrinsics: (F, 3, 3) K per keyframe.
        with_jacobians: also return the Jacobians (else they are empty arrays).

    """
    # Relative poses host -> observer for every keyframe pair (F^2 << M), then per observation.
    rot_pairs = state.rotation[None] @ np.swapaxes(state.rotation, -1, -2)[:, None]  # [h, j]
    t_pairs = state.translation[None] - np.einsum('hjab,hb->hja', rot_pairs, state.translation)
    h = host[obs_track]
    rot_jh, t_jh = rot_pairs[h, obs_frame], t_pairs[h, obs_frame]
    rho = state.inv_depth[obs_track]
    point_h = rays[obs_track] / rho[:, None]
    point_j = np.einsum('mij,mj->mi', rot_jh, point_h) + t_jh
    k = intrinsics[obs_frame]
    fx, fy = k[:, 0, 0], k[:, 1, 1]
    z = point_j[:, 2]
    pixel = np.stack([fx * point_j[:, 0] / z + k[:, 0, 2], fy * point_j[:, 1] / z + k[:, 1, 2]],
                     axis=-1)
    residual = pixel - obs_xy
    if not with_jacobians:
        empty = np.empty((0,))
        return Reprojection(residual, empty, empty, empty)
    d_pix = np.zeros((len(z), 2, 3))
    d_pix[:, 0, 0] = fx / z
    d_pix[:, 0, 2] = -fx * point_j[:, 0] / z**2
    d_pix[:, 1, 1] = fy / z
    d_pix[:, 1, 2] = -fy * point_j[:, 1] / z**2
    eye = np.broadcast_to(np.eye(3), (len(z), 3, 3))
    d_target = np.concatenate([eye, -lie.skew(point_j)], axis=-1)
    d_host = -rot_jh @ np.concatenate([eye, -lie.skew(point_h)], axis=-1)
    d_rho = -np.einsum('mij,mj->mi', rot_jh, rays[obs_track]) / rho[:, None] ** 2
    return Reprojection(residual, d_pix @ d_host, d_pix @ d_target,
                        np.einsum('mij,mj->mi', d_pix, d_rho))


def pose_prior(state: PoseState, pairs: np.ndarray, T_rel: np.ndarray, sigma_m: float,
               sigma_rad: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Whitened relative-pose prior residuals (R, 6) and Jacobians (R, 6, 6) for poses i and j.

    The error pose is ``E = M^-1 G_i G_j^-1`` with ``M`` the measured ``T_cam_i_cam_j``; the
    residual is ``(t_E / sigma_m, rotvec(R_E) / sigma_rad)``.
    """
    rot_m_inv, t_m_inv = lie.inverse(T_rel[:, :3, :3], T_rel[:, :3, 3])
    i, j = pairs[:, 0], pairs[:, 1]
    rot_j_inv, t_j_inv = lie.inverse(state.rotation[j], state.translation[j])
    rot_ij = state.rotation[i] @ rot_j_inv
    t_ij = np.einsum('rab,rb->ra', state.rotation[i], t_j_inv) + state.translation[i]
    rot_e = rot_m_inv @ rot_ij
    t_e = np.einsum('rab,rb->ra', rot_m_inv, t_ij) + t_m_inv
    scale = np.array([1.0 / sigma_m] * 3 + [1.0 / sigma_rad] * 3)
    residual = np.concatenate([t_e, Rotation.from_matrix(rot_e).as_rotvec()], axis=-1) * scale
    # First-order Jacobians (the rotation part ignores the inverse left Jacobian of rotvec).
    d_e = np.zeros((len(pairs), 6, 6))
    d_e[:, :3, :3] = np.eye(3)
    d_e[:, :3, 3:] = -lie.skew(t_e)
    d_e[:, 3:, 3:] = np.eye(3)
    jac_i = d_e @ lie.adjoint(rot_m_inv, t_m_inv)
    jac_j = np.zeros((len(pairs), 6, 6))
    jac_j[:, :3, :3] = -rot_e
    jac_j[:, 3:, 3:] = -rot_e
    return residual, scale[:, None] * jac_i, scale[:, None] * jac_j


def huber_weight(error: np.ndarray, threshold: float) -> np.ndarray:
    """IRLS weights ``min(1, threshold / error)`` of the Huber loss on error norms (M,)."""
    return np.minimum(1.0, threshold / np.maximum(error, 1e-12))


def huber_cost(error: np.ndarray, threshold: float) -> np.ndarray:
    """Twice the Huber loss of error norms (M,): ``e^2`` inside, ``2 d e - d^2`` outside."""
    return np.where(error <= threshold, error**2, 2.0 * threshold * error - threshold**2)
