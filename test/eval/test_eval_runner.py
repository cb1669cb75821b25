"""Tests of the evaluation runner: sources, scoring, baselines, prediction files, plots, CLI."""

import dataclasses
import json
from pathlib import Path

import cv2
from engine_configs import seeded_tiny
from infinihand_ros.core.errors import InputError
from infinihand_ros.engine.settings import load_engine_config
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.eval import baselines
from infinihand_ros.eval.cli import main
from infinihand_ros.eval.cli import mean_pose_joints
from infinihand_ros.eval.prediction_files import read_predictions
from infinihand_ros.eval.prediction_files import write_predictions
from infinihand_ros.eval.runner import aggregate
from infinihand_ros.eval.runner import evaluate
from infinihand_ros.eval.runner import Predictions
from infinihand_ros.eval.runner import run_engine
from infinihand_ros.eval.runner import score_sequence
from infinihand_ros.eval.sequences import EvalSequence
from infinihand_ros.eval.sequences import open_eval_sequence
from infinihand_ros.mano.mirror import mirror_axis_angle
from infinihand_ros.synth.cli import generate
from infinihand_ros.synth.sequence import SynthConfig
import numpy as np
import pytest

FRAMES = 16


@pytest.fixture(scope='module')
def synth_output(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Return a short generator output (bag + samples) at 15 FPS, 160 x 120."""
    out = tmp_path_factory.mktemp('eval_sequence') / 'seq_31'
    generate(SynthConfig(fps=15.0, width=160, height=120), seed=31, frames=FRAMES, out=out,
             progress=False)
    return out


@pytest.fixture(scope='module')
def sequence(synth_output: Path) -> EvalSequence:
    return open_eval_sequence(synth_output)


def _perfect(sequence: EvalSequence) -> Predictions:
    """Predictions equal to the ground truth (every visible hand, every pose)."""
    truth = sequence.truth
    visible = truth.visible
    return Predictions(
        timestamp_ns=truth.timestamp_ns, has_result=np.ones(truth.num_frames, bool),
        T_world_cam=truth.T_world_cam, hand_valid=visible.copy(),
        confidence=visible.astype(float), joints_cam=truth.joints_cam,
        joints_world=np.where(visible[..., None, None], truth.joints_world, np.nan),
        rotation_cam=truth.rotation_cam, box_xyxy=truth.box_xyxy, frames_per_s=1.0)


def test_generator_output_and_its_bag_give_the_same_truth(synth_output: Path,
                                                          sequence: EvalSequence) -> None:
    from_bag = open_eval_sequence(synth_output / 'bag')
    assert sequence.name == from_bag.name == 'seq_31'
    assert sequence.fps == pytest.approx(15.0) and from_bag.fps == pytest.approx(15.0)
    np.testing.assert_array_equal(sequence.truth.timestamp_ns, from_bag.truth.timestamp_ns)
    np.testing.assert_allclose(sequence.truth.T_world_cam, from_bag.truth.T_world_cam,
                               atol=1e-6)
    np.testing.assert_array_equal(sequence.truth.visible, from_bag.truth.visible)
    visible = sequence.truth.visible
    assert visible.any()
    np.testing.assert_allclose(sequence.truth.joints_world[visible],
                               from_bag.truth.joints_world[visible], atol=1e-5)
    frames = list(from_bag.frames())
    assert len(frames) == FRAMES and frames[0][0].shape == (120, 160, 3)


def test_perfect_predictions_score_zero_and_the_baselines_do_not(
        sequence: EvalSequence) -> None:
    mean_pose = baselines.mean_pose_joints(np.zeros((15, 3)))
    result = aggregate([score_sequence(sequence, _perfect(sequence), mean_pose)])
    ours = result.ours
    assert ours['Recall'] == 1.0 and ours['F1'] == 1.0 and ours['FAcc'] == 1.0
    for name in ('W-MPJPE', 'PA-MPJPE', 'WA-MPJPE', 'MP-p', 'PA-p', 'CT-p'):
        assert ours[name] == pytest.approx(0.0, abs=1e-6), name
    assert ours['ATE'] == pytest.approx(0.0, abs=1e-9)
    assert ours['RPE-r'] == pytest.approx(0.0, abs=1e-4)
    static, mean_hand = result.baselines['static-camera'], result.baselines['mean-hand']
    # The head moves, so holding the first camera misplaces the hands and the trajectory.
    assert static['W-MPJPE'] > 1.0 and static['ATE'] > 1e-3
    assert static['PA-MPJPE'] == pytest.approx(0.0, abs=1e-6)  # same hands, per-pair aligned
    assert mean_hand['W-MPJPE'] > 1.0
    assert result.baselines['mean-pose']['PA-MPJPE'] > 1.0


def test_missing_results_and_hands_leave_the_scored_pairs(sequence: EvalSequence) -> None:
    pred = _perfect(sequence)
    has_result = pred.has_result.copy()
    has_result[3] = False
    hand_valid = pred.hand_valid.copy()
    hand_valid[5] = False
    pred = dataclasses.replace(pred, has_result=has_result, hand_valid=hand_valid)
    mean_pose = baselines.mean_pose_joints(np.zeros((15, 3)))
    evaluation = score_sequence(sequence, pred, mean_pose)
    assert not evaluation.matched[3].any() and not evaluation.matched[5].any()
    assert sequence.truth.visible[5].any()  # so frame 5's hands are misses now
    assert aggregate([evaluation]).ours['Recall'] < 1.0


def test_without_a_training_mean_the_sequences_own_mean_is_used(
        sequence: EvalSequence) -> None:
    joints, source = mean_pose_joints(None, seeded_tiny(), [sequence])
    assert source == 'evaluated sequences'
    truth = sequence.truth
    poses = [truth.hand_pose[truth.visible[:, side], side] for side in (0, 1)]
    expected = baselines.mean_pose_joints(baselines.mean_articulation(poses, [0, 1]))
    np.testing.assert_allclose(joints, expected)


def test_mean_articulation_mirrors_left_hands() -> None:
    rng = np.random.default_rng(0)
    pose = rng.normal(scale=0.3, size=(15, 3))
    mean = baselines.mean_articulation([pose[None], mirror_axis_angle(pose)[None]], [1, 0])
    np.testing.assert_allclose(mean, pose, atol=1e-9)
    joints = baselines.mean_pose_joints(pose)
    assert joints.shape == (2, 21, 3)
    np.testing.assert_allclose(joints[0] * [-1, 1, 1], joints[1], atol=1e-9)


def test_engine_run_files_round_trip_and_plots(sequence: EvalSequence, tmp_path: Path) -> None:
    """The tiny (seeded) engine over the short sequence: shapes, prediction file, plots."""
    config = load_engine_config()
    result = evaluate([sequence], lambda: StreamingEngine(config),
                      baselines.mean_pose_joints(np.zeros((15, 3))))
    item = result.sequences[0]
    pred = item.predictions
    assert pred.has_result.all() and pred.frames_per_s > 0
    assert np.isfinite(pred.T_world_cam).all()
    assert result.ours['ATE'] >= 0.0 and 'Recall' in result.ours
    path = tmp_path / 'seq.npz'
    write_predictions(path, pred)
    back = read_predictions(path)
    np.testing.assert_array_equal(back['timestamp_ns'], pred.timestamp_ns)
    np.testing.assert_array_equal(back['hand_valid'], pred.hand_valid)
    np.testing.assert_array_equal(back['T_world_cam'], pred.T_world_cam)
    np.testing.assert_array_equal(back['joints_world'], pred.joints_world)


def test_live_poses_are_the_published_ones_and_final_poses_the_refined(
        sequence: EvalSequence) -> None:
    """``poses='live'`` scores what push/flush returned; ``'final'`` what refined() returns."""
    config = load_engine_config()

    def engine_poses(refine: bool) -> np.ndarray:
        with StreamingEngine(config) as engine:
            results = [result for rgb, stamp, intrinsics in sequence.frames()
                       for result in engine.push(rgb, stamp, intrinsics)]
            results += engine.flush()
            if refine:
                results = engine.refined(results)
        return np.stack([result.camera_pose.matrix() for result in results])

    for poses, refine in (('live', False), ('final', True)):
        with StreamingEngine(config) as engine:
            pred = run_engine(sequence, engine, poses)
        np.testing.assert_allclose(pred.T_world_cam, engine_poses(refine), atol=1e-9)
    with StreamingEngine(config) as engine, pytest.raises(ValueError, match='poses: expected'):
        run_engine(sequence, engine, 'smoothed')


def test_broken_prediction_file_is_refused(tmp_path: Path) -> None:
    path = tmp_path / 'bad.npz'
    np.savez(path, joints_world=np.zeros((3, 2, 21, 3)), hand_valid=np.zeros((3, 2)),
             T_world_cam=np.zeros((3, 4, 4)), timestamp_ns=np.zeros(3, np.int64))
    with pytest.raises(InputError, match='hand_valid has shape'):
        read_predictions(path)


def test_cli_json_line_files_and_usage_errors(synth_output: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / 'eval'
    assert main(['--sequences', str(synth_output), '--json', '--save-predictions',
                 str(out)]) == 0
    line = capsys.readouterr().out.strip().splitlines()
    assert len(line) == 1
    report = json.loads(line[0])
    assert set(report) == {'ours', 'baselines', 'sequences', 'detection_breakdown', 'settings'}
    breakdown = report['detection_breakdown']
    side_targets = [group['targets'] for group in breakdown['by_side'].values()]
    assert sum(side_targets) > 0
    assert sum(side_targets) == sum(group['targets'] for group in breakdown['by_size'].values())
    assert set(report['baselines']) == {'static-camera', 'mean-hand', 'mean-pose'}
    assert report['sequences'][0]['name'] == 'seq_31'
    assert report['settings']['mean_pose'].startswith('training set (')  # the bundled model's
    assert report['settings']['poses'] == 'final'
    assert report['settings']['hand_source'] == 'infinihand'  # config/engine.yaml's
    assert read_predictions(out / 'seq_31.npz')['T_world_cam'].shape == (FRAMES, 4, 4)
    for name in ('seq_31_top_view.png', 'seq_31_errors.png'):
        image = cv2.imread(str(out / name))
        assert image is not None and image.std() > 0
    assert main(['--sequences', str(tmp_path / 'missing')]) == 2
    assert 'no such file or directory' in capsys.readouterr().err
