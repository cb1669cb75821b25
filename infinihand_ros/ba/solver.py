"""Levenberg-Marquardt bundle adjustment with the inverse depths eliminated by a Schur complement.

Cost: confidence-weighted reprojection errors (Huber IRLS first, then the observations above the
gate are dropped and plain least squares follows), plus a depth prior per track (it fixes the
monocular scale), optional loose relative-pose priors between keyframe pairs and, where the
problem frees it, a prior on the shared lens (focal scale and radial k1; ``ba.costs``). The
normal equations are summed per observation into dense arrays (6F pose unknowns for F keyframes
and the lens's 2 after them, and a (6F + 2, P) pose/depth block); each inverse depth is a 1x1
block, so the Schur complement onto the poses is element-wise and the reduced system is solved
by Cholesky.
"""

from dataclasses import dataclass
from dataclasses import replace
import logging
from typing import Final

from infinihand_ros.ba import costs
from infinihand_ros.ba import lie
from infinihand_ros.ba.config import SolverConfig
from infinihand_ros.ba.problem import BAProblem
from infinihand_ros.ba.problem import BAResult
from infinihand_ros.core import geometry
from infinihand_ros.core.errors import InputError
import numpy as np
from scipy import linalg

logger = logging.getLogger(__name__)

#: Damping factor change on a rejected / accepted step, and its bounds.
DAMPING_UP: Final = 10.0
DAMPING_DOWN: Final = 0.1
MAX_DAMPING: Final = 1e8
MIN_DAMPING: Final = 1e-9
#: Added to the inverse-depth diagonal so tracks left without measurements stay solvable.
DEPTH_DIAGONAL_FLOOR: Final = 1e-12
POSE_DOF: Final = 6


@dataclass(frozen=True)
class _Normal:
    """Normal equations ``H x = g`` split into pose (p) and inverse-depth (d) parts."""

    h_pp: np.ndarray  # (6F + 2, 6F + 2): poses, then the lens
    h_pd: np.ndarray  # (6F + 2, P)
    h_dd: np.ndarray  # (P,) diagonal
    g_p: np.ndarray  # (6F + 2,)
    g_d: np.ndarray  # (P,)


@dataclass(frozen=True)
class _Layout:
    """Per-problem constants: where each term lands in the normal equations."""

    obs_columns: np.ndarray  # (M, C) unknowns of each observation: host, observer (12), and
    #                          the lens (2) where the problem frees it
    obs_flat: np.ndarray  # (M * C * C,) places of their CxC blocks in the raveled h_pp
    depth_flat: np.ndarray  # (M * C,) places of their pose/depth terms in the raveled h_pd
    prior_columns: np.ndarray  # (R, 12) pose unknowns of each relative-pose prior
    prior_flat: np.ndarray  # (R * 144,)


class BundleAdjuster:
    """Solve ``BAProblem``s with the settings of one ``SolverConfig``."""

    def __init__(self, config: SolverConfig) -> None:
        """Keep the solver settings."""
        self.config = config

    def solve(self, problem: BAProblem) -> BAResult:
        """Refine the free keyframe poses and all inverse depths of ``problem``.

        Raises:
            InputError: when the scale gauge is free (no depth prior and fewer than two fixed
                poses).

        """
        if not problem.has_depth_prior and np.count_nonzero(problem.fixed) < 2:
            raise InputError('BA problem: no depth prior and one fixed pose leave the scale free; '
                             'give depth priors or fix the two oldest keyframes')
        rot, trans = lie.inverse(problem.T_world_cam[:, :3, :3], problem.T_world_cam[:, :3, 3])
        state = costs.PoseState(rot, trans, problem.inv_depth.astype(np.float64),
                                np.array(problem.lens, dtype=np.float64))
        layout = _make_layout(problem)
        weights = problem.obs_weight.astype(np.float64)
        initial_cost = self._cost(problem, layout, state, weights, robust=True)
        state, irls_iterations = self._run_lm(problem, layout, state, weights, robust=True,
                                              iterations=self.config.irls_iterations)
        error = np.linalg.norm(self._reprojection(problem, layout, state, False).residual, axis=-1)
        inliers = error <= self.config.gate_px
        weights = np.where(inliers, weights, 0.0)
        state, ls_iterations = self._run_lm(problem, layout, state, weights, robust=False,
                                            iterations=self.config.max_iterations)
        final_cost = self._cost(problem, layout, state, weights, robust=False)
        logger.debug('BA: %d frames, %d tracks, %d/%d inliers, cost %.4g -> %.4g',
                     problem.num_frames, len(problem.host), inliers.sum(), len(inliers),
                     initial_cost, final_cost)
        rot_wc, t_wc = lie.inverse(state.rotation, state.translation)
        T_world_cam = geometry.make_transform(rot_wc, t_wc)
        T_world_cam[problem.fixed] = problem.T_world_cam[problem.fixed]
        return BAResult(T_world_cam, state.inv_depth, inliers, initial_cost, final_cost,
                        irls_iterations + ls_iterations, state.lens.copy())

    def _run_lm(self, problem: BAProblem, layout: _Layout, state: costs.PoseState,
                weights: np.ndarray, robust: bool, iterations: int) -> tuple[costs.PoseState, int]:
        """Run up to ``iterations`` accepted LM steps; return the state and the steps taken."""
        damping = self.config.initial_damping
        cost = self._cost(problem, layout, state, weights, robust)
        for iteration in range(iterations):
            normal = self._normal_equations(problem, layout, state, weights, robust)
            while damping < MAX_DAMPING:
                candidate = self._step(problem, state, normal, damping)
                new_cost = (np.inf if candidate is None
                            else self._cost(problem, layout, candidate, weights, robust))
                if new_cost < cost:
                    break
                damping *= DAMPING_UP
            else:
                return state, iteration
            decrease = (cost - new_cost) / max(cost, 1e-300)
            state, cost = candidate, new_cost
            damping = max(damping * DAMPING_DOWN, MIN_DAMPING)
            if decrease < self.config.min_relative_decrease:
                return state, iteration + 1
        return state, iterations

    def _reprojection(self, problem: BAProblem, layout: _Layout, state: costs.PoseState,
                      with_jacobians: bool) -> costs.Reprojection:
        """Reprojection residuals (and Jacobians, the lens's where it is free)."""
        rays = costs.host_rays(problem.intrinsics, problem.host, problem.host_xy, state.lens)
        return costs.reprojection(state, rays, problem.host, problem.obs_track,
                                  problem.obs_frame, problem.obs_xy, problem.intrinsics,
                                  with_jacobians,
                                  problem.host_xy if problem.lens_free.any() else None)

    def _pose_prior_on(self, problem: BAProblem) -> bool:
        """Return whether relative-pose priors are part of the cost."""
        return self.config.rel_pose_sigma_m > 0 and len(problem.prior_pairs) > 0

    def _cost(self, problem: BAProblem, layout: _Layout, state: costs.PoseState,
              weights: np.ndarray, robust: bool) -> float:
        """Total cost: weighted (Huber or squared) reprojection + depth and pose priors."""
        error = np.linalg.norm(self._reprojection(problem, layout, state, False).residual, axis=-1)
        per_obs = costs.huber_cost(error, self.config.huber_px) if robust else error**2
        total = float(np.sum(weights * per_obs))
        has_prior = np.isfinite(problem.prior_inv_depth)
        depth_residual = ((state.inv_depth - problem.prior_inv_depth)[has_prior]
                          / problem.prior_sigma[has_prior])
        total += float(np.sum(depth_residual**2))
        free = problem.lens_free
        total += float(np.sum(((state.lens - problem.lens)[free]
                               / problem.lens_sigma[free])**2))
        if self._pose_prior_on(problem):
            residual, _, _ = costs.pose_prior(state, problem.prior_pairs, problem.prior_T_rel,
                                              self.config.rel_pose_sigma_m,
                                              self.config.rel_pose_sigma_rad)
            total += float(np.sum(residual**2))
        return total

    def _normal_equations(self, problem: BAProblem, layout: _Layout, state: costs.PoseState,
                          weights: np.ndarray, robust: bool) -> _Normal:
        """Linearise the cost at ``state`` (IRLS weights when ``robust``)."""
        reproj = self._reprojection(problem, layout, state, True)
        if robust:
            error = np.linalg.norm(reproj.residual, axis=-1)
            weights = weights * costs.huber_weight(error, self.config.huber_px)
        sqrt_w = np.sqrt(weights)[:, None]
        num_tracks, size = len(problem.host), _size(problem)
        blocks = [reproj.jac_host, reproj.jac_target]
        if problem.lens_free.any():
            blocks.append(reproj.jac_lens)
        jac = np.concatenate(blocks, axis=-1) * sqrt_w[..., None]
        residual = reproj.residual * sqrt_w
        h_pp, g_p = _pose_blocks(layout.obs_columns, layout.obs_flat, jac, residual, size)
        jac_depth = reproj.jac_inv_depth * sqrt_w
        h_pd = np.bincount(layout.depth_flat, np.einsum('mri,mr->mi', jac, jac_depth).ravel(),
                           minlength=size * num_tracks).reshape(size, num_tracks)
        h_dd = np.bincount(problem.obs_track, np.sum(jac_depth**2, axis=-1),
                           minlength=num_tracks)
        g_d = -np.bincount(problem.obs_track, np.sum(jac_depth * residual, axis=-1),
                           minlength=num_tracks)
        if self._pose_prior_on(problem):
            prior_r, jac_i, jac_j = costs.pose_prior(
                state, problem.prior_pairs, problem.prior_T_rel, self.config.rel_pose_sigma_m,
                self.config.rel_pose_sigma_rad)
            prior_h, prior_g = _pose_blocks(layout.prior_columns, layout.prior_flat,
                                            np.concatenate([jac_i, jac_j], axis=-1), prior_r,
                                            size)
            h_pp += prior_h
            g_p += prior_g
        has_prior = np.isfinite(problem.prior_inv_depth)
        inv_var = np.where(has_prior, 1.0 / problem.prior_sigma**2, 0.0)
        h_dd += inv_var
        g_d -= np.where(has_prior, (state.inv_depth - problem.prior_inv_depth) * inv_var, 0.0)
        lens = slice(size - costs.LENS_DOF, size)
        lens_inv_var = np.zeros(costs.LENS_DOF)
        lens_inv_var[problem.lens_free] = 1.0 / problem.lens_sigma[problem.lens_free]**2
        h_pp[lens, lens] += np.diag(lens_inv_var)
        g_p[lens] -= lens_inv_var * (state.lens - problem.lens)
        return _Normal(h_pp, h_pd, h_dd, g_p, g_d)

    def _step(self, problem: BAProblem, state: costs.PoseState, normal: _Normal,
              damping: float) -> costs.PoseState | None:
        """Solve the damped system by the Schur complement; None when it is not positive."""
        free = _free_unknowns(problem)
        h_dd = normal.h_dd * (1.0 + damping) + DEPTH_DIAGONAL_FLOOR
        h_pp = normal.h_pp[np.ix_(free, free)]
        h_pp[np.diag_indices_from(h_pp)] *= 1.0 + damping
        h_pd = normal.h_pd[free]
        scaled = h_pd / h_dd
        reduced = h_pp - scaled @ h_pd.T
        rhs = normal.g_p[free] - scaled @ normal.g_d
        try:
            delta_free = (linalg.cho_solve(linalg.cho_factor(reduced), rhs) if len(rhs)
                          else np.zeros(0))
        except linalg.LinAlgError:
            return None
        delta = np.zeros(_size(problem))
        delta[free] = delta_free
        delta_depth = (normal.g_d - h_pd.T @ delta_free) / h_dd
        poses = POSE_DOF * problem.num_frames
        rotation, translation = lie.retract(state.rotation, state.translation,
                                            delta[:poses].reshape(-1, POSE_DOF))
        inv_depth = np.maximum(state.inv_depth + delta_depth, self.config.min_inverse_depth)
        return replace(state, rotation=rotation, translation=translation, inv_depth=inv_depth,
                       lens=state.lens + delta[poses:])


def _size(problem: BAProblem) -> int:
    """Return the number of unknowns in the pose system: 6 per keyframe, then the lens."""
    return POSE_DOF * problem.num_frames + costs.LENS_DOF


def _free_unknowns(problem: BAProblem) -> np.ndarray:
    """Return (6F + 2,) bool: the free poses' unknowns and the free lens unknowns."""
    return np.r_[np.repeat(~problem.fixed, POSE_DOF), problem.lens_free]


def _pose_columns(first: np.ndarray, second: np.ndarray,
                  lens: np.ndarray | None = None) -> np.ndarray:
    """Return the unknowns (N, 12) of two poses per item: 6 of ``first``, then 6 of ``second``.

    With ``lens`` (the lens unknowns' columns), they follow: (N, 12 + 2).
    """
    offsets = np.arange(POSE_DOF)
    parts = [POSE_DOF * first[:, None] + offsets, POSE_DOF * second[:, None] + offsets]
    if lens is not None:
        parts.append(np.broadcast_to(lens, (len(first), len(lens))))
    return np.concatenate(parts, axis=1)


def _flat_blocks(columns: np.ndarray, size: int) -> np.ndarray:
    """Return where each item's 12x12 block lands in a raveled (size, size) matrix: (N * 144,)."""
    return (columns[:, :, None] * size + columns[:, None, :]).ravel()


def _make_layout(problem: BAProblem) -> _Layout:
    """Return the problem's normal-equation indices (fixed during a solve)."""
    size, num_tracks = _size(problem), len(problem.host)
    lens = np.arange(size - costs.LENS_DOF, size) if problem.lens_free.any() else None
    obs_columns = _pose_columns(problem.host[problem.obs_track], problem.obs_frame, lens)
    prior_columns = _pose_columns(problem.prior_pairs[:, 0], problem.prior_pairs[:, 1])
    return _Layout(obs_columns, _flat_blocks(obs_columns, size),
                   (obs_columns * num_tracks + problem.obs_track[:, None]).ravel(),
                   prior_columns, _flat_blocks(prior_columns, size))


def _pose_blocks(columns: np.ndarray, flat: np.ndarray, jac: np.ndarray, residual: np.ndarray,
                 size: int) -> tuple[np.ndarray, np.ndarray]:
    """Sum per-item Gauss-Newton terms into the pose system.

    Args:
        columns: (N, 12) pose unknowns of each item (from ``_pose_columns``).
        flat: (N * 144,) their blocks' places (from ``_flat_blocks``).
        jac: (N, R, 12) whitened Jacobians of each item's R residuals w.r.t. those unknowns.
        residual: (N, R) whitened residuals.
        size: number of unknowns in the pose system (6F + 2).

    Returns:
        ``J^T J`` (size, size) and ``-J^T r`` (size,).

    """
    jtj = np.swapaxes(jac, -1, -2) @ jac
    hessian = np.bincount(flat, jtj.ravel(), minlength=size * size).reshape(size, size)
    gradient = -np.bincount(columns.ravel(), np.einsum('nri,nr->ni', jac, residual).ravel(),
                            minlength=size)
    return hessian, gradient
