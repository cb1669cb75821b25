"""Levenberg-Marquardt bundle adjustment with the inverse depths eliminated by a Schur complement.

Cost: confidence-weighted reprojection errors (Huber IRLS first, then the observations above the
gate are dropped and plain least squares follows), plus a depth prior per track (it fixes the
monocular scale) and optional loose relative-pose priors between keyframe pairs. The normal
equations are summed per observation into dense arrays (6F pose unknowns for F keyframes, and
a (6F, P) pose/depth block); each inverse depth is a 1x1 block, so the Schur complement onto the
poses is element-wise and the reduced system is solved by Cholesky.
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
import torch

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

    h_pp: np.ndarray  # (6F, 6F)
    h_pd: np.ndarray  # (6F, P)
    h_dd: np.ndarray  # (P,) diagonal
    g_p: np.ndarray  # (6F,)
    g_d: np.ndarray  # (P,)


@dataclass(frozen=True)
class _Layout:
    """Per-problem constants: host rays and where each term lands in the normal equations."""

    rays: np.ndarray  # (P, 3) host rays
    obs_columns: np.ndarray  # (M, 12) pose unknowns of each observation (host, observer)
    obs_flat: np.ndarray  # (M * 144,) places of their 12x12 blocks in the raveled h_pp
    depth_flat: np.ndarray  # (M * 12,) places of their pose/depth terms in the raveled h_pd
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
        state = costs.PoseState(rot, trans, problem.inv_depth.astype(np.float64))
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
                        irls_iterations + ls_iterations)

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
        """Reprojection residuals (and Jacobians) of every observation."""
        return costs.reprojection(state, layout.rays, problem.host, problem.obs_track,
                                  problem.obs_frame, problem.obs_xy, problem.intrinsics,
                                  with_jacobians)

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
        num_tracks, size = len(problem.host), POSE_DOF * problem.num_frames
        jac = np.concatenate([reproj.jac_host, reproj.jac_target], axis=-1) * sqrt_w[..., None]
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
        return _Normal(h_pp, h_pd, h_dd, g_p, g_d)

    def _step(self, problem: BAProblem, state: costs.PoseState, normal: _Normal,
              damping: float) -> costs.PoseState | None:
        """Solve the damped system by the Schur complement; None when it is not positive."""
        free = np.repeat(~problem.fixed, POSE_DOF)
        h_dd = normal.h_dd * (1.0 + damping) + DEPTH_DIAGONAL_FLOOR
        h_pp = normal.h_pp[np.ix_(free, free)]
        h_pp[np.diag_indices_from(h_pp)] *= 1.0 + damping
        # The (6F, P) products run in torch so that they follow the process's torch thread
        # setting; numpy's BLAS would start its own threads beside the stream's model.
        h_pd = torch.from_numpy(normal.h_pd[free])
        scaled = torch.from_numpy(normal.h_pd[free] / h_dd)
        reduced = h_pp - (scaled @ h_pd.T).numpy()
        rhs = normal.g_p[free] - (scaled @ torch.from_numpy(normal.g_d)).numpy()
        try:
            delta_free = linalg.cho_solve(linalg.cho_factor(reduced), rhs)
        except linalg.LinAlgError:
            return None
        delta_pose = np.zeros(POSE_DOF * problem.num_frames)
        delta_pose[free] = delta_free
        delta_depth = (normal.g_d - (h_pd.T @ torch.from_numpy(delta_free)).numpy()) / h_dd
        rotation, translation = lie.retract(state.rotation, state.translation,
                                            delta_pose.reshape(-1, POSE_DOF))
        inv_depth = np.maximum(state.inv_depth + delta_depth, self.config.min_inverse_depth)
        return replace(state, rotation=rotation, translation=translation, inv_depth=inv_depth)


def _pose_columns(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Return the unknowns (N, 12) of two poses per item: 6 of ``first``, then 6 of ``second``."""
    offsets = np.arange(POSE_DOF)
    return np.concatenate([POSE_DOF * first[:, None] + offsets,
                           POSE_DOF * second[:, None] + offsets], axis=1)


def _flat_blocks(columns: np.ndarray, size: int) -> np.ndarray:
    """Return where each item's 12x12 block lands in a raveled (size, size) matrix: (N * 144,)."""
    return (columns[:, :, None] * size + columns[:, None, :]).ravel()


def _make_layout(problem: BAProblem) -> _Layout:
    """Return the problem's host rays and normal-equation indices (fixed during a solve)."""
    size, num_tracks = POSE_DOF * problem.num_frames, len(problem.host)
    obs_columns = _pose_columns(problem.host[problem.obs_track], problem.obs_frame)
    prior_columns = _pose_columns(problem.prior_pairs[:, 0], problem.prior_pairs[:, 1])
    return _Layout(costs.host_rays(problem.intrinsics, problem.host, problem.host_xy),
                   obs_columns, _flat_blocks(obs_columns, size),
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
        size: number of pose unknowns (6F).

    Returns:
        ``J^T J`` (size, size) and ``-J^T r`` (size,).

    """
    jtj = np.swapaxes(jac, -1, -2) @ jac
    hessian = np.bincount(flat, jtj.ravel(), minlength=size * size).reshape(size, size)
    gradient = -np.bincount(columns.ravel(), np.einsum('nri,nr->ni', jac, residual).ravel(),
                            minlength=size)
    return hessian, gradient
