"""A BA result is used only where it explains tracks it never saw better than its start did.

Every ``holdout_every``-th track is kept out of the fit. After the solve, each held-out track's
inverse depth is fitted (poses and lens held, the same depth prior) twice: once with the poses and
lens BA started from, once with BA's. The refinement is accepted when its robust (Huber)
reprojection cost per held-out observation is lower by at least ``holdout_min_gain`` (a share
of the start's); otherwise the start stands. A BA whose poses fit its own tracks but not the
scene (a moving object tracked as scene, a bad local minimum) fails the check, and so does one
that moves the poses without explaining the images clearly better (a start the images cannot
improve on: moving it would only add the solution's own errors).
"""

from dataclasses import dataclass
from dataclasses import replace
from typing import Final

from infinihand_ros.ba import costs
from infinihand_ros.ba.config import SolverConfig
from infinihand_ros.ba.problem import BAProblem
from infinihand_ros.ba.solver import BundleAdjuster
from infinihand_ros.core import geometry
import numpy as np

#: Fewer held-out observations than this: the check cannot judge, the refinement is refused.
MIN_HELD_OUT_OBSERVATIONS: Final = 20
#: Depth-only iterations when the held-out tracks are fitted to a set of poses.
DEPTH_ITERATIONS: Final = 5
#: No held-out observation is gated away: the check scores all of them (robustly).
HUGE_GATE_PX: Final = 1e9


@dataclass(frozen=True)
class HoldoutCheck:
    """The held-out test of one BA call.

    Attributes:
        accepted: the refinement lowers the held-out cost by at least the required share.
        initial_cost: Huber cost per held-out observation with the starting poses and lens (px^2).
        refined_cost: the same with BA's poses and lens.
        observations: held-out observations compared.

    """

    accepted: bool
    initial_cost: float
    refined_cost: float
    observations: int


def split_holdout(problem: BAProblem, every: int) -> tuple[BAProblem, BAProblem]:
    """Return (the problem to fit, the held-out problem): every ``every``-th track held out."""
    held = np.arange(len(problem.host)) % every == every - 1
    return problem.tracks(~held), problem.tracks(held)


def held_out_cost(held: BAProblem, T_world_cam: np.ndarray, lens: np.ndarray,
                  config: SolverConfig) -> float:
    """Return the Huber cost per observation of ``held``'s tracks on these poses and lens.

    The tracks' inverse depths are fitted first (every pose and the lens held).
    """
    return float(np.mean(held_out_costs(held, T_world_cam, lens, config)))


def held_out_costs(held: BAProblem, T_world_cam: np.ndarray, lens: np.ndarray,
                   config: SolverConfig) -> np.ndarray:
    """Return the Huber cost (M,) of each of ``held``'s observations (``held_out_cost``)."""
    depth_only = replace(config, irls_iterations=DEPTH_ITERATIONS, max_iterations=1,
                         gate_px=HUGE_GATE_PX)
    posed = replace(held, T_world_cam=T_world_cam, fixed=np.ones(held.num_frames, dtype=bool),
                    lens=np.asarray(lens, dtype=np.float64), lens_sigma=np.zeros(costs.LENS_DOF))
    fitted = BundleAdjuster(depth_only).solve(posed)
    world_to_cam = geometry.invert_transform(T_world_cam)
    state = costs.PoseState(world_to_cam[:, :3, :3], world_to_cam[:, :3, 3], fitted.inv_depth,
                            np.asarray(lens, dtype=np.float64))
    rays = costs.host_rays(held.intrinsics, held.host, held.host_xy, state.lens)
    residual = costs.reprojection(state, rays, held.host, held.obs_track, held.obs_frame,
                                  held.obs_xy, held.intrinsics, False).residual
    return costs.huber_cost(np.linalg.norm(residual, axis=-1), config.huber_px)


def check_refinement(held: BAProblem, T_refined: np.ndarray, lens_refined: np.ndarray,
                     config: SolverConfig) -> HoldoutCheck:
    """Compare the held-out cost of the start (``held``'s poses and lens) with BA's result."""
    count = len(held.obs_track)
    if count < MIN_HELD_OUT_OBSERVATIONS:
        return HoldoutCheck(False, np.nan, np.nan, count)
    initial = held_out_cost(held, held.T_world_cam, held.lens, config)
    refined = held_out_cost(held, T_refined, lens_refined, config)
    accepted = refined <= initial * (1.0 - config.holdout_min_gain)
    return HoldoutCheck(bool(accepted), initial, refined, count)
