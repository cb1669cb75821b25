"""The held-out check: a BA result is used only where it fits tracks it never saw."""

from dataclasses import replace

from ba_builders import make_problem
from ba_builders import synth_keyframe
from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import SolverConfig
from infinihand_ros.ba.corrections import CorrectionTrack
from infinihand_ros.ba.features import FeatureCache
from infinihand_ros.ba.keyframe import BAOutput
from infinihand_ros.ba.solver import BundleAdjuster
from infinihand_ros.ba.validation import check_refinement
from infinihand_ros.ba.validation import split_holdout
from infinihand_ros.ba.worker import BARequest
from infinihand_ros.ba.worker import BundleAdjustmentWorker
from infinihand_ros.ba.worker import plan_request
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

SOLVER = SolverConfig(rel_pose_sigma_m=0.0)


def test_held_out_tracks_never_enter_the_fit(rng) -> None:
    """Every 5th track is held out; the two problems share poses and split tracks and views."""
    problem = make_problem(rng, num_frames=6, num_tracks=200).problem
    fit, held = split_holdout(problem, 5)
    assert len(held.host) == 40 and len(fit.host) == 160
    assert len(fit.obs_track) + len(held.obs_track) == len(problem.obs_track)
    np.testing.assert_array_equal(held.host_xy, problem.host_xy[4::5])
    assert fit.T_world_cam is problem.T_world_cam


def test_a_refinement_that_fits_better_passes_and_a_bent_one_is_refused(rng) -> None:
    """BA from a noisy start passes; the same poses turned by 1 deg per frame do not."""
    synthetic = make_problem(rng, num_frames=8, num_tracks=300, pixel_noise=0.5,
                             pose_noise=0.02)
    fit, held = split_holdout(synthetic.problem, 5)
    result = BundleAdjuster(SOLVER).solve(fit)
    good = check_refinement(held, result.T_world_cam, result.lens, SOLVER)
    assert good.accepted and good.refined_cost < 0.5 * good.initial_cost
    bent = result.T_world_cam.copy()
    turn = Rotation.from_rotvec([0.0, np.radians(1.0), 0.0]).as_matrix()
    for index in range(1, len(bent)):
        bent[index, :3, :3] = np.linalg.matrix_power(turn, index) @ bent[index, :3, :3]
    start_at_truth = replace(held, T_world_cam=synthetic.T_world_cam)
    refused = check_refinement(start_at_truth, bent, result.lens, SOLVER)
    assert not refused.accepted and refused.refined_cost > 2 * refused.initial_cost
    assert refused.observations == len(held.obs_track)


def test_too_few_held_out_observations_refuse_the_refinement(rng) -> None:
    """A check that cannot judge does not let the result through."""
    problem = make_problem(rng, num_frames=3, num_tracks=20).problem
    fit, held = split_holdout(problem, 10)
    check = check_refinement(held, problem.T_world_cam, np.zeros(2), SOLVER)
    assert not check.accepted and check.observations < 20


def _reject_all(request: BARequest, config: BAConfig, cache: FeatureCache) -> BAOutput:
    """Return a result whose held-out check failed: the start poses stand."""
    keyframes = request.keyframes
    return BAOutput(np.array([k.frame_id for k in keyframes]),
                    np.array([k.timestamp_ns for k in keyframes]),
                    np.stack([k.T_world_cam for k in keyframes]), request.T_world_cam,
                    0, 0, 0, 0.0, 0.0, accepted=False, held_out_costs=(1.0, 2.0))


class _RejectingWorker(BundleAdjustmentWorker):
    run_function = staticmethod(_reject_all)


def test_a_rejected_call_is_counted_and_its_frames_are_flagged(keyframes_3: list) -> None:
    """The worker counts the rejection and reports its frames as unrefined."""
    with _RejectingWorker(BAConfig()) as worker:
        worker.submit(plan_request(keyframes_3, CorrectionTrack()))
        assert worker.wait_idle(60.0)
        stats = worker.statistics
        assert (stats.done, stats.rejected, stats.failed) == (1, 1, 0)
        assert worker.failed_frame_ids == {k.frame_id for k in keyframes_3}
        output, = worker.poll()
    assert not output.accepted
    np.testing.assert_array_equal(output.T_world_cam_refined, output.T_world_cam_raw)


@pytest.fixture(scope='module')
def keyframes_3() -> list:
    """Return 3 keyframes of a synthetic sequence (true poses)."""
    sequence = SyntheticSequence(SynthConfig(), seed=3, num_frames=6)
    return [synth_keyframe(sequence.frame(index)) for index in range(0, 6, 2)]
