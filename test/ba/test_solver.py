"""LM + Schur BA: same optimum as independent solvers, scale held, outliers gated."""

from dataclasses import replace

from ba_builders import K
from ba_builders import make_problem
from ba_builders import SyntheticBA
from infinihand_ros.ba.config import SolverConfig
from infinihand_ros.ba.problem import BAProblem
from infinihand_ros.ba.solver import BundleAdjuster
from infinihand_ros.core import geometry
from infinihand_ros.core.errors import InputError
import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

#: Plain least squares run to convergence: no IRLS, no gating (the oracles have neither).
EXACT = SolverConfig(irls_iterations=0, max_iterations=50, gate_px=1e6,
                     min_relative_decrease=1e-14, rel_pose_sigma_m=0.05, rel_pose_sigma_rad=0.02)


def _position_error(poses: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Return camera position distances (F,) in metres."""
    return np.linalg.norm(poses[:, :3, 3] - reference[:, :3, 3], axis=-1)


def _oracle_residuals(x: np.ndarray, problem: BAProblem, config: SolverConfig) -> np.ndarray:
    """Whitened residuals of the solver's cost, written independently with 4x4 matrices."""
    free = np.flatnonzero(~problem.fixed)
    twists = x[:6 * len(free)].reshape(-1, 6)
    inv_depth = x[6 * len(free):]
    world_to_cam = geometry.invert_transform(problem.T_world_cam)
    delta = geometry.make_transform(Rotation.from_rotvec(twists[:, 3:]).as_matrix(), twists[:, :3])
    world_to_cam[free] = delta @ world_to_cam[free]
    T_world_cam = geometry.invert_transform(world_to_cam)
    rays = np.c_[(problem.host_xy - K[:2, 2]) / np.diag(K)[:2], np.ones(len(problem.host))]
    points_host = rays / inv_depth[:, None]
    track = problem.obs_track
    cam_from_host = world_to_cam[problem.obs_frame] @ T_world_cam[problem.host[track]]
    points = geometry.transform_points(cam_from_host, points_host[track][:, None])[:, 0]
    reprojection = (geometry.project_points(points, K) - problem.obs_xy).ravel()
    has_prior = np.isfinite(problem.prior_inv_depth)
    depth = ((inv_depth - problem.prior_inv_depth) / problem.prior_sigma)[has_prior]
    i, j = problem.prior_pairs.T
    error = geometry.invert_transform(problem.prior_T_rel) @ world_to_cam[i] @ T_world_cam[j]
    pose = np.c_[error[:, :3, 3] / config.rel_pose_sigma_m,
                 Rotation.from_matrix(error[:, :3, :3]).as_rotvec() / config.rel_pose_sigma_rad]
    return np.concatenate([reprojection, depth, pose.ravel()])


def _oracle_solve(problem: BAProblem, config: SolverConfig) -> np.ndarray:
    """Return the poses (F, 4, 4) that scipy's least_squares reaches on the identical cost."""
    num_free = np.count_nonzero(~problem.fixed)
    x0 = np.r_[np.zeros(6 * num_free), problem.inv_depth]
    solution = least_squares(_oracle_residuals, x0, args=(problem, config), method='trf',
                             x_scale='jac', ftol=1e-15, xtol=1e-15, gtol=1e-15)
    free = np.flatnonzero(~problem.fixed)
    world_to_cam = geometry.invert_transform(problem.T_world_cam)
    twists = solution.x[:6 * num_free].reshape(-1, 6)
    delta = geometry.make_transform(Rotation.from_rotvec(twists[:, 3:]).as_matrix(), twists[:, :3])
    world_to_cam[free] = delta @ world_to_cam[free]
    return geometry.invert_transform(world_to_cam)


def test_same_optimum_as_scipy_least_squares_on_the_identical_cost(rng) -> None:
    """Reprojection + depth prior + relative-pose prior: both solvers agree to 1e-6 m."""
    synthetic = make_problem(rng, num_frames=5, num_tracks=80, with_pose_prior=True)
    ours = BundleAdjuster(EXACT).solve(synthetic.problem)
    oracle = _oracle_solve(synthetic.problem, EXACT)
    assert ours.inliers.all()
    assert _position_error(ours.T_world_cam, oracle).max() < 1e-6
    assert geometry.rotation_angle_deg(ours.T_world_cam[:, :3, :3],
                                       oracle[:, :3, :3]).max() < 1e-5
    # The optimum is a real improvement over the noisy start.
    assert (_position_error(ours.T_world_cam, synthetic.T_world_cam).max()
            < 0.3 * _position_error(synthetic.problem.T_world_cam, synthetic.T_world_cam).max())


def _colmap_solve(problem: BAProblem) -> np.ndarray:
    """Return the poses (F, 4, 4) pycolmap (Ceres) reaches with 3D points as variables."""
    pycolmap = pytest.importorskip('pycolmap')
    from colmap_oracle import colmap_bundle_adjust
    return colmap_bundle_adjust(pycolmap, problem, K)


@pytest.mark.parametrize('pixel_noise', [0.0, 0.5])
def test_same_optimum_as_pycolmap(rng, pixel_noise: float) -> None:
    """Without priors and with two fixed poses, ours and pycolmap's BA reach the same poses.

    Pycolmap keeps each track's host observation as a residual, while ours puts the point on
    the host ray, so with noisy pixels the optima differ slightly; noise-free they coincide.
    """
    synthetic = make_problem(rng, num_frames=6, num_tracks=150, pixel_noise=pixel_noise,
                             with_depth_prior=False, num_fixed=2)
    ours = BundleAdjuster(EXACT).solve(synthetic.problem).T_world_cam
    colmap = _colmap_solve(synthetic.problem)
    start = _position_error(synthetic.problem.T_world_cam, synthetic.T_world_cam).max()
    if pixel_noise == 0.0:
        assert _position_error(ours, colmap).max() < 1e-6
        assert _position_error(ours, synthetic.T_world_cam).max() < 1e-6
    else:
        assert _position_error(ours, colmap).max() < 0.1 * start
        assert _position_error(ours, synthetic.T_world_cam).max() < 0.2 * start


def _scale_drifted(synthetic: SyntheticBA, factor: float, prior_sigma: float) -> BAProblem:
    """Return the problem with true poses and depths scaled by ``factor`` about frame 0."""
    poses = synthetic.T_world_cam.copy()
    poses[:, :3, 3] *= factor
    problem = synthetic.problem
    return replace(problem, T_world_cam=poses, inv_depth=synthetic.inv_depth / factor,
                   prior_sigma=prior_sigma * problem.prior_inv_depth)


def test_depth_prior_holds_the_scale(rng) -> None:
    """From a start whose scale drifted by 30 %, the depth prior restores it within 2 %.

    The start has zero reprojection error (scale is invisible to it), so a prior too weak to
    matter leaves the drift in place: the depth prior is what holds the scale.
    """
    synthetic = make_problem(rng, num_frames=8, num_tracks=200, pixel_noise=0.3)
    true_length = np.linalg.norm(synthetic.T_world_cam[-1, :3, 3])
    solver = BundleAdjuster(SolverConfig(rel_pose_sigma_m=0.0))
    held = solver.solve(_scale_drifted(synthetic, 1.3, prior_sigma=0.05)).T_world_cam
    loose = solver.solve(_scale_drifted(synthetic, 1.3, prior_sigma=1e4)).T_world_cam
    assert np.linalg.norm(held[-1, :3, 3]) / true_length == pytest.approx(1.0, abs=0.02)
    assert np.linalg.norm(loose[-1, :3, 3]) / true_length == pytest.approx(1.3, abs=0.02)


def test_outliers_are_gated_and_do_not_bend_the_poses(rng) -> None:
    """5 % of observations moved by 10-40 px are dropped; poses end within 1 cm of the truth."""
    synthetic = make_problem(rng, num_frames=8, num_tracks=300)
    problem = synthetic.problem
    bad = rng.random(len(problem.obs_track)) < 0.05
    offset = rng.uniform(10.0, 40.0, bad.sum())[:, None] * rng.choice([-1.0, 1.0], (bad.sum(), 2))
    obs_xy = problem.obs_xy.copy()
    obs_xy[bad] += offset
    result = BundleAdjuster(SolverConfig(rel_pose_sigma_m=0.0)).solve(
        replace(problem, obs_xy=obs_xy))
    assert np.mean(~result.inliers[bad]) > 0.9
    assert np.mean(result.inliers[~bad]) > 0.98
    assert _position_error(result.T_world_cam, synthetic.T_world_cam).max() < 0.01
    assert result.final_cost < result.initial_cost


def test_bad_problems_are_refused(rng) -> None:
    """No gauge, a free scale or a wrong shape raise an error naming the fix."""
    problem = make_problem(rng, num_frames=4, num_tracks=30).problem
    with pytest.raises(InputError, match='no fixed pose'):
        replace(problem, fixed=np.zeros(4, dtype=bool))
    with pytest.raises(InputError, match='inv_depth has shape'):
        replace(problem, inv_depth=problem.inv_depth[:-1])
    free_scale = replace(problem, prior_inv_depth=np.full(30, np.nan))
    with pytest.raises(InputError, match='scale free'):
        BundleAdjuster(SolverConfig()).solve(free_scale)


#: A real lens the intrinsics do not describe: focal length 6 % longer, barrel distortion.
TRUE_LENS = (np.log(1.06), -0.15)


def test_the_shared_lens_is_recovered_and_straightens_the_poses(rng) -> None:
    """Pixels through an unknown lens: refining it finds focal and k1, and the poses follow.

    Holding the pinhole instead leaves the poses several times further from the truth (the
    failure of BA on real head-camera clips whose distortion nobody gave).
    """
    synthetic = make_problem(rng, num_frames=8, num_tracks=300, pixel_noise=0.3,
                             lens=TRUE_LENS)
    problem = synthetic.problem
    solver = BundleAdjuster(replace(EXACT, rel_pose_sigma_m=0.0))
    free = solver.solve(replace(problem, lens_sigma=np.array([0.2, 0.5])))
    held = solver.solve(problem)
    assert free.lens[0] == pytest.approx(TRUE_LENS[0], abs=0.01)
    assert free.lens[1] == pytest.approx(TRUE_LENS[1], abs=0.01)
    free_error = _position_error(free.T_world_cam, synthetic.T_world_cam).max()
    held_error = _position_error(held.T_world_cam, synthetic.T_world_cam).max()
    assert free_error < 0.01 and held_error > 3 * free_error


def test_lens_optimum_matches_pycolmap_simple_radial(rng) -> None:
    """With two fixed poses and no depth prior, ours and pycolmap's SIMPLE_RADIAL BA agree.

    Both refine one shared focal length and k1 with the poses (our lens prior made negligible);
    noise-free, both reach the same poses and lens.
    """
    pycolmap = pytest.importorskip('pycolmap')
    from colmap_oracle import colmap_bundle_adjust
    synthetic = make_problem(rng, num_frames=6, num_tracks=200, pixel_noise=0.0,
                             with_depth_prior=False, num_fixed=2, lens=TRUE_LENS)
    problem = replace(synthetic.problem, lens_sigma=np.array([1e3, 1e3]))
    ours = BundleAdjuster(EXACT).solve(problem)
    poses, focal, k1 = colmap_bundle_adjust(pycolmap, problem, K, refine_lens=True)
    assert _position_error(ours.T_world_cam, poses).max() < 1e-5
    assert K[0, 0] * np.exp(ours.lens[0]) == pytest.approx(focal, rel=1e-5)
    assert ours.lens[1] == pytest.approx(k1, abs=1e-5)
    assert focal == pytest.approx(K[0, 0] * np.exp(TRUE_LENS[0]), rel=1e-4)
