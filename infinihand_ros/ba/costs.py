"""Residuals and Jacobians of the BA cost: reprojection, depth prior, relative-pose prior.

All functions are vectorised over observations, tracks and pose pairs. Poses are world-to-camera
``(R, t)``, perturbed on the left with twists ``(v, omega)`` (see ``ba.lie``); a track's point is
``X_host = ray / rho`` with ``ray`` the host pixel's undistorted ray at unit depth.

The lens is shared by every keyframe of a problem: each keyframe's pinhole K with its focal
lengths scaled by ``exp(lens[0])`` and one radial coefficient ``k1 = lens[1]`` (COLMAP's
SIMPLE_RADIAL model: normalised point ``n`` seen at ``n (1 + k1 |n|^2)``). ``lens = (0, 0)`` is
the plain pinhole of K.
"""

from dataclasses import dataclass
from dataclasses import field
from dataclasses import replace
from typing import Final

from infinihand_ros.ba import lie
import numpy as np
from scipy.spatial.transform import Rotation

#: Lens unknowns: log focal scale, radial k1.
LENS_DOF: Final = 2
#: Fixed-point iterations that undistort a host pixel (|k1 r^2| < 0.3: error < 1e-6 px).
UNDISTORT_ITERATIONS: Final = 12
#: Step of the numerical lens Jacobian.
LENS_STEP: Final = 1e-6


@dataclass(frozen=True)
class PoseState:
    """Current values of the BA variables.

    Attributes:
        rotation: (F, 3, 3) world-to-camera rotations.
        translation: (F, 3) world-to-camera translations (m).
        inv_depth: (P,) per-track inverse depths (1/m).
        lens: (2,) log focal scale and radial k1 shared by every keyframe.

    """

    rotation: np.ndarray
    translation: np.ndarray
    inv_depth: np.ndarray
    lens: np.ndarray = field(default_factory=lambda: np.zeros(LENS_DOF))


@dataclass(frozen=True)
class Reprojection:
    """Reprojection residuals (M, 2) in px and their Jacobians.

    Attributes:
        residual: (M, 2) projected minus observed pixel.
        jac_host: (M, 2, 6) w.r.t. the host pose's twist.
        jac_target: (M, 2, 6) w.r.t. the observing pose's twist.
        jac_inv_depth: (M, 2) w.r.t. the track's inverse depth.
        jac_lens: (M, 2, 2) w.r.t. the lens (log focal scale, k1); empty unless asked for.

    """

    residual: np.ndarray
    jac_host: np.ndarray
    jac_target: np.ndarray
    jac_inv_depth: np.ndarray
    jac_lens: np.ndarray = field(default_factory=lambda: np.empty((0,)))


def host_rays(intrinsics: np.ndarray, host: np.ndarray, host_xy: np.ndarray,
              lens: np.ndarray | None = None) -> np.ndarray:
    """Return unit-depth rays (P, 3) of the tracks' host pixels, undistorted by ``lens``."""
    log_focal, k1 = (0.0, 0.0) if lens is None else lens
    k = intrinsics[host]
    scale = np.exp(log_focal)
    distorted = np.stack([(host_xy[:, 0] - k[:, 0, 2]) / (k[:, 0, 0] * scale),
                          (host_xy[:, 1] - k[:, 1, 2]) / (k[:, 1, 1] * scale)], axis=-1)
    normal = distorted
    if k1 != 0.0:
        for _ in range(UNDISTORT_ITERATIONS):
            normal = distorted / (1.0 + k1 * np.sum(normal**2, axis=-1, keepdims=True))
    return np.c_[normal, np.ones(len(normal))]


def reprojection(state: PoseState, rays: np.ndarray, host: np.ndarray, obs_track: np.ndarray,
                 obs_frame: np.ndarray, obs_xy: np.ndarray, intrinsics: np.ndarray,
                 with_jacobians: bool = True, host_xy: np.ndarray | None = None
                 ) -> Reprojection:
    """Reproject every observation's track from its host into the observing keyframe.

    Args:
        state: current poses, inverse depths and lens.
        rays: (P, 3) host rays from ``host_rays`` with ``state.lens``.
        host: (P,) host keyframe per track.
        obs_track: (M,) track per observation.
        obs_frame: (M,) observing keyframe per observation.
        obs_xy: (M, 2) observed pixels.
        intrinsics: (F, 3, 3) K per keyframe.
        with_jacobians: also return the Jacobians (else they are empty arrays).
        host_xy: (P, 2) host pixels: with Jacobians, also the lens Jacobian (numerical; the
            host rays move with the lens too).

    """
    out = _reprojection(state, rays, host, obs_track, obs_frame, obs_xy, intrinsics,
                        with_jacobians)
    if not with_jacobians or host_xy is None:
        return out
    columns = []
    for axis in range(LENS_DOF):
        lens = state.lens.copy()
        lens[axis] += LENS_STEP
        moved = replace(state, lens=lens)
        shifted = _reprojection(moved, host_rays(intrinsics, host, host_xy, lens), host,
                                obs_track, obs_frame, obs_xy, intrinsics, False)
        columns.append((shifted.residual - out.residual) / LENS_STEP)
    return replace(out, jac_lens=np.stack(columns, axis=-1))


def _reprojection(state: PoseState, rays: np.ndarray, host: np.ndarray, obs_track: np.ndarray,
                  obs_frame: np.ndarray, obs_xy: np.ndarray, intrinsics: np.ndarray,
                  with_jacobians: bool) -> Reprojection:
    """Reprojection residuals and their pose and depth Jacobians (``reprojection``)."""
    # Relative poses host -> observer for every keyframe pair (F^2 << M), then per observation.
    rot_pairs = state.rotation[None] @ np.swapaxes(state.rotation, -1, -2)[:, None]  # [h, j]
    t_pairs = state.translation[None] - np.einsum('hjab,hb->hja', rot_pairs, state.translation)
    h = host[obs_track]
    rot_jh, t_jh = rot_pairs[h, obs_frame], t_pairs[h, obs_frame]
    rho = state.inv_depth[obs_track]
    point_h = rays[obs_track] / rho[:, None]
    point_j = np.einsum('mij,mj->mi', rot_jh, point_h) + t_jh
    k = intrinsics[obs_frame]
    log_focal, k1 = state.lens
    focal = np.stack([k[:, 0, 0], k[:, 1, 1]], axis=-1) * np.exp(log_focal)
    z = point_j[:, 2]
    normal = point_j[:, :2] / z[:, None]
    radial = 1.0 + k1 * np.sum(normal**2, axis=-1)
    residual = focal * normal * radial[:, None] + k[:, :2, 2] - obs_xy
    if not with_jacobians:
        empty = np.empty((0,))
        return Reprojection(residual, empty, empty, empty)
    # d pixel / d normal = f ((1 + k1 r^2) I + 2 k1 n n^T); d normal / d point = [I/z, -n/z].
    d_dist = (radial[:, None, None] * np.eye(2)
              + 2.0 * k1 * normal[:, :, None] * normal[:, None, :]) * focal[:, :, None]
    d_normal = np.zeros((len(z), 2, 3))
    d_normal[:, 0, 0] = d_normal[:, 1, 1] = 1.0 / z
    d_normal[:, :, 2] = -normal / z[:, None]
    d_pix = d_dist @ d_normal
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
