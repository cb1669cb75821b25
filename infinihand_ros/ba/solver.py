"""Levenberg-Marquardt bundle adjustment with the inverse depths eliminated by a Schur complement.

Cost: confidence-weighted reprojection errors (Huber IRLS first, then the observations above the
gate are dropped and plain least squares follows), plus a depth prior per track (it fixes the
monocular scale) and optional loose relative-pose priors between keyframe pairs. The normal
equations are built with sparse products; each inverse depth is a 1x1 block, so the Schur
complement onto the 6F pose unknowns is element-wise and the reduced system is solved by Cholesky.
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
from scipy import sparse

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
    h_pd: sparse.csr_matrix  # (6F, P)
    h_dd: np.ndarray  # (P,) diagonal
    g_p: np.ndarray  # (6F,)
    g_d: np.ndarray  # (P,)


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
        rays = costs.host_rays(problem.intrinsics, problem.host, problem.host_xy)
        weights = problem.obs_weight.astype(np.float64)
        initial_cost = self._cost(problem, rays, state, weights, robust=True)
        state, irls_iterations = self._run_lm(problem, rays, state, weights, robust=True,
                                              iterations=self.config.irls_iterations)
        error = np.linalg.norm(self._reprojection(problem, rays, state, False).residual, axis=-1)
        inliers = error <= self.config.gate_px
        weights = np.where(inliers, weights, 0.0)
        state, ls_iterations = self._run_lm(problem, rays, state, weights, robust=False,
                                            iterations=self.config.max_iterations)
        final_cost = self._cost(problem, rays, state, weights, robust=False)
        logger.debug('BA: %d frames, %d tracks, %d/%d inliers, cost %.4g -> %.4g',
                     problem.num_frames, len(problem.host), inliers.sum(), len(inliers),
                     initial_cost, final_cost)
        rot_wc, t_wc = lie.inverse(state.rotation, state.translation)
        T_world_cam = geometry.make_transform(rot_wc, t_wc)
        T_world_cam[problem.fixed] = problem.T_world_cam[problem.fixed]
        return BAResult(T_world_cam, state.inv_depth, inliers, initial_cost, final_cost,
                        irls_iterations + ls_iterations)

    def _run_lm(self, problem: BAProblem, rays: np.ndarray, state: costs.PoseState,
                weights: np.ndarray, robust: bool, iterations: int) -> tuple[costs.PoseState, int]:
        """Run up to ``iterations`` accepted LM steps; return the state and the steps taken."""
        damping = self.config.initial_damping
        cost = self._cost(problem, rays, state, weights, robust)
        for iteration in range(iterations):
            normal = self._normal_equations(problem, rays, state, weights, robust)
            while damping < MAX_DAMPING:
                candidate = self._step(problem, state, normal, damping)
                new_cost = (np.inf if candidate is None
                            else self._cost(problem, rays, candidate, weights, robust))
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

    def _reprojection(self, problem: BAProblem, rays: np.ndarray, state: costs.PoseState,
                      with_jacobians: bool) -> costs.Reprojection:
        """Reprojection residuals (and Jacobians) of every observation."""
        return costs.reprojection(state, rays, problem.host, problem.obs_track, problem.obs_frame,
                                  problem.obs_xy, problem.intrinsics, with_jacobians)

    def _pose_prior_on(self, problem: BAProblem) -> bool:
        """Return whether relative-pose priors are part of the cost."""
        return self.config.rel_pose_sigma_m > 0 and len(problem.prior_pairs) > 0

    def _cost(self, problem: BAProblem, rays: np.ndarray, state: costs.PoseState,
              weights: np.ndarray, robust: bool) -> float:
        """Total cost: weighted (Huber or squared) reprojection + depth and pose priors."""
        error = np.linalg.norm(self._reprojection(problem, rays, state, False).residual, axis=-1)
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

    def _normal_equations(self, problem: BAProblem, rays: np.ndarray, state: costs.PoseState,
                          weights: np.ndarray, robust: bool) -> _Normal:
        """Linearise the cost at ``state`` (IRLS weights when ``robust``)."""
        reproj = self._reprojection(problem, rays, state, True)
        if robust:
            error = np.linalg.norm(reproj.residual, axis=-1)
            weights = weights * costs.huber_weight(error, self.config.huber_px)
        sqrt_w = np.sqrt(weights)[:, None]
        num_obs, num_frames = len(weights), problem.num_frames
        host = problem.host[problem.obs_track]
        rows = [np.repeat(np.arange(2 * num_obs).reshape(-1, 2), POSE_DOF, axis=1)] * 2
        cols = [_pose_columns(host, 2), _pose_columns(problem.obs_frame, 2)]
        data = [(reproj.jac_host * sqrt_w[..., None]).reshape(num_obs, 2 * POSE_DOF),
                (reproj.jac_target * sqrt_w[..., None]).reshape(num_obs, 2 * POSE_DOF)]
        residual = [(reproj.residual * sqrt_w).ravel()]
        if self._pose_prior_on(problem):
            prior_r, jac_i, jac_j = costs.pose_prior(
                state, problem.prior_pairs, problem.prior_T_rel, self.config.rel_pose_sigma_m,
                self.config.rel_pose_sigma_rad)
            num_pairs = len(prior_r)
            prior_rows = 2 * num_obs + np.arange(POSE_DOF * num_pairs).reshape(-1, POSE_DOF)
            rows += [np.repeat(prior_rows, POSE_DOF, axis=1)] * 2
            cols += [_pose_columns(problem.prior_pairs[:, 0], POSE_DOF),
                     _pose_columns(problem.prior_pairs[:, 1], POSE_DOF)]
            data += [jac_i.reshape(num_pairs, -1), jac_j.reshape(num_pairs, -1)]
            residual.append(prior_r.ravel())
        residual = np.concatenate(residual)
        jac_pose = sparse.csr_matrix(
            (np.concatenate([d.ravel() for d in data]),
             (np.concatenate([r.ravel() for r in rows]),
              np.concatenate([c.ravel() for c in cols]))),
            shape=(len(residual), POSE_DOF * num_frames))
        jac_depth_values = (reproj.jac_inv_depth * sqrt_w).ravel()
        jac_depth = sparse.csr_matrix(
            (jac_depth_values, (np.arange(2 * num_obs), np.repeat(problem.obs_track, 2))),
            shape=(len(residual), len(problem.host)))
        h_dd = np.bincount(np.repeat(problem.obs_track, 2), jac_depth_values**2,
                           minlength=len(problem.host))
        g_d = -(jac_depth.T @ residual)
        has_prior = np.isfinite(problem.prior_inv_depth)
        inv_var = np.where(has_prior, 1.0 / problem.prior_sigma**2, 0.0)
        h_dd += inv_var
        g_d -= np.where(has_prior, (state.inv_depth - problem.prior_inv_depth) * inv_var, 0.0)
        return _Normal((jac_pose.T @ jac_pose).toarray(), (jac_pose.T @ jac_depth).tocsr(), h_dd,
                       -(jac_pose.T @ residual), g_d)

    def _step(self, problem: BAProblem, state: costs.PoseState, normal: _Normal,
              damping: float) -> costs.PoseState | None:
        """Solve the damped system by the Schur complement; None when it is not positive."""
        free = np.repeat(~problem.fixed, POSE_DOF)
        h_dd = normal.h_dd * (1.0 + damping) + DEPTH_DIAGONAL_FLOOR
        h_pp = normal.h_pp[np.ix_(free, free)]
        h_pp[np.diag_indices_from(h_pp)] *= 1.0 + damping
        h_pd = normal.h_pd[free]
        reduced = h_pp - (h_pd @ sparse.diags(1.0 / h_dd) @ h_pd.T).toarray()
        rhs = normal.g_p[free] - h_pd @ (normal.g_d / h_dd)
        try:
            delta_free = linalg.cho_solve(linalg.cho_factor(reduced), rhs)
        except linalg.LinAlgError:
            return None
        delta_pose = np.zeros(POSE_DOF * problem.num_frames)
        delta_pose[free] = delta_free
        delta_depth = (normal.g_d - h_pd.T @ delta_free) / h_dd
        rotation, translation = lie.retract(state.rotation, state.translation,
                                            delta_pose.reshape(-1, POSE_DOF))
        inv_depth = np.maximum(state.inv_depth + delta_depth, self.config.min_inverse_depth)
        return replace(state, rotation=rotation, translation=translation, inv_depth=inv_depth)


def _pose_columns(frames: np.ndarray, rows_per_item: int) -> np.ndarray:
    """Column indices (N, rows_per_item * 6) of the pose blocks of ``frames``, row-major."""
    block = POSE_DOF * frames[:, None] + np.arange(POSE_DOF)
    return np.tile(block, (1, rows_per_item))
