"""Benchmark scripts: bad arguments refused with one line; the error-source summary."""

import importlib.util
import json
import math
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest
from real_stills import STILLS

BENCHMARKS = Path(__file__).resolve().parents[1] / 'benchmarks'


def test_throughput_refuses_fewer_than_three_frames() -> None:
    """--frames 2 exits 2 with argparse's one-line error naming the minimum."""
    run = subprocess.run([sys.executable, str(BENCHMARKS / 'throughput.py'), '--frames', '2'],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert '--frames must be at least 3, got 2' in run.stderr


def test_profile_times_every_stage_of_a_few_frames() -> None:
    """benchmarks/profile_engine.py runs on 3 sample-bag frames and times the stages used."""
    run = subprocess.run([sys.executable, str(BENCHMARKS / 'profile_engine.py'), '--frames', '3',
                          '--modes', 'per_frame', '--json'],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    figures = json.loads(run.stdout.strip().splitlines()[-1])
    stages = figures['per_frame']['stages_ms_per_frame']
    for stage in ('decode (JPEG)', 'geometry branch/aggregator', 'depth head (on demand)',
                  'engine bookkeeping/tracker', 'publishing (build, serialise)'):
        assert stages[stage] > 0, stage
    assert figures['per_frame']['fps'] > 0


def _benchmark(name: str):
    """Import benchmarks/<name>.py (a script, not a package module)."""
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f'{name}.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_error_sources_summary_averages_sequences_and_frame_ranges() -> None:
    """Placements average over sequences; frame ranges pool frames, skipping unscored ones."""
    sources = _benchmark('eval_error_sources')
    nan = float('nan')

    def figures(w_mpjpe: float, errors: list[float]) -> dict:
        scores = {'W-MPJPE': w_mpjpe, 'WA-MPJPE': w_mpjpe / 2}
        return {'scores': dict.fromkeys(sources.PLACEMENTS, scores),
                'rotation_error_deg': errors, 'step_error_deg': errors,
                'true_step_deg': [0.0] + [1.0] * (len(errors) - 1)}

    result = sources.summary([figures(100.0, [0.0, 2.0, nan, 4.0, 4.0, 8.0]),
                              figures(300.0, [0.0, 6.0, 6.0, 6.0, 6.0, 6.0])])
    assert result['placements']['ours'] == {'W-MPJPE': 200.0, 'WA-MPJPE': 100.0}
    first, second = result['rotation_by_frames']
    # frames 1-4: (2 + 4 + 4) of the first sequence (its NaN skipped), 4 x 6 of the second
    assert first == {'frames': '1-5', 'rotation_error_deg': pytest.approx(34.0 / 7),
                     'step_error_deg': pytest.approx(34.0 / 7), 'true_step_deg': 1.0}
    assert second['frames'] == '5-6' and second['rotation_error_deg'] == 7.0


def test_gpu_check_runs_on_the_tiny_model_on_the_cpu(tmp_path: Path) -> None:
    """benchmarks/gpu_check.py (the prepared GPU check) runs end to end in CPU mode."""
    out = tmp_path / 'gpu_check.json'
    run = subprocess.run([sys.executable, str(BENCHMARKS / 'gpu_check.py'), '--size', 'tiny',
                          '--device', 'cpu', '--frames', '3', '--out', str(out)],
                         capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    figures = json.loads(out.read_text())
    assert set(figures['stream']) == {'per_frame', 'windowed', 'live'}
    assert figures['stream']['live']['pacing']['paced']
    for stream in (*figures['stream'].values(), figures['converted']):
        assert stream['frames'] == 3 and stream['fps'] > 0 and stream['peak_memory_mib'] > 0
    assert figures['converted']['matched_tensors'] > 0
    step = figures['train_step']
    assert step['steps'] == 1 and step['step_seconds'] > 0 and math.isfinite(step['loss'])


def test_synth_realism_reports_consistent_overall_figures() -> None:
    """benchmarks/synth_realism.py runs MediaPipe on 4 synthetic frames; its counts agree."""
    run = subprocess.run([sys.executable, str(BENCHMARKS / 'synth_realism.py'), '--seeds', '0',
                          '--frames', '4', '--real-stills', '2', '--json'],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout.strip().splitlines()[-1])
    overall = report['overall']
    assert overall['frames'] == 4 and overall['visible'] > 0
    assert 0 <= overall['found'] <= overall['found_any'] <= overall['visible']
    assert overall['found_share'] == overall['found'] / overall['visible']
    assert (overall['found_overlapping'] <= overall['visible_overlapping']
            <= overall['visible_whole'])
    assert overall['found_whole'] <= overall['found'] and 0 <= overall['found_cut_share'] <= 1
    assert 0 <= overall['found_isolated_share'] <= 1
    assert overall['pck'] is None or 0 <= overall['pck'] <= 1
    assert overall['false_positives'] >= 0 and overall['mediapipe_ms_per_frame'] > 0
    bins = report['joint_bins']
    assert list(bins) == ['21', '19-20', '16-18', '10-15', '1-9']
    assert all(0 <= found <= found_any <= hands for hands, found, found_any in bins.values())
    assert bins['21'][0] == overall['visible_whole'] - overall['visible_overlapping']
    assert sum(hands for hands, _, _ in bins.values()) <= overall['visible']
    views = report['views']
    assert list(views) == ['back', 'back, oblique', 'edge-on', 'palm']
    assert [sum(column) for column in zip(*views.values())] == bins['21']
    if STILLS.is_dir():  # the real reference: the first two stills' hands panned out and in
        real = report['real_reference']
        assert list(real['views']) == list(views)
        assert [sum(column) for column in zip(*real['views'].values())] == [
            a + b for a, b in zip(real['leaving']['21'], real['entering']['21'])]
        for pans in (real['leaving'], real['entering']):
            assert list(pans) == list(bins)
            assert pans['21'][0] > 0
            assert all(0 <= found <= found_any <= hands
                       for hands, found, found_any in pans.values())
        # The same frames in reverse order: the same hands per bin.
        assert ([hands for hands, _, _ in real['leaving'].values()]
                == [hands for hands, _, _ in real['entering'].values()])
    else:
        assert 'real_reference' not in report


def test_synth_realism_sorts_hands_by_the_side_the_camera_sees() -> None:
    """A hand showing the camera its palm, its back or its edge falls in that view bin."""
    from types import SimpleNamespace
    from infinihand_ros.core.hand_conventions import SIDES
    from infinihand_ros.mano.builtin import canonical_joints
    from scipy.spatial.transform import Rotation
    realism = _benchmark('synth_realism')
    for side in SIDES:
        joints = canonical_joints(side)  # fingers along x, the palm facing -y
        for degrees, view in ((90.0, 'palm'), (-90.0, 'back'), (-25.0, 'back, oblique'),
                              (0.0, 'edge-on')):
            turned = Rotation.from_euler('x', degrees, degrees=True).apply(joints)
            truth = SimpleNamespace(joints_cam=turned + [0.0, 0.0, 0.5], side=side)
            assert realism._truth_view(truth) == view, (side, degrees)


def test_synth_realism_pans_move_the_hand_out_through_one_border() -> None:
    """The real reference's crop windows start on the hand, end past the border, stay inside."""
    realism = _benchmark('synth_realism')
    box = np.array([300.0, 200.0, 340.0, 250.0])  # 40 x 50 px: windows 175 x 131 px
    centres, width = realism.pan_windows(box, (0, 1), (640, 480), (336, 252))
    assert width == pytest.approx(realism.PAN_CROP_BOXES * 50.0)
    assert np.allclose(centres[0], [320.0, 225.0]) and np.allclose(centres[:, 0], 320.0)
    height = width * 252 / 336
    assert box[1] > centres[-1, 1] + height / 2  # the whole box below the window's bottom
    assert box[3] < centres[0, 1] + height / 2  # ... which it started inside
    assert len(centres) == realism.PAN_STEPS
    near_edge, _ = realism.pan_windows(np.array([10.0, 200.0, 50.0, 250.0]), (1, 0),
                                       (640, 480), (336, 252))
    assert len(near_edge) == 0  # the first window would leave the photo: no pan


def test_synth_realism_moves_joints_into_crops_exactly() -> None:
    """A dot at a joint in a photo lands where ``crop_joints`` puts the joint in the crop."""
    from infinihand_ros.core.datatypes import Intrinsics
    from infinihand_ros.synth.photo_streams import crop_stream
    realism = _benchmark('synth_realism')
    photo = np.zeros((480, 640, 3), np.uint8)
    joint = np.array([[402.0, 251.0]])
    photo[250:253, 401:404] = 255  # a 3 x 3 dot centred on the joint
    k = Intrinsics(500.0, 500.0, 320.0, 240.0, 640, 480)
    crop = crop_stream(photo, k, np.array([[380.0, 230.0]]), np.array([168.0]), (336, 252))[0]
    moved = realism.crop_joints(joint, k, crop.intrinsics)[0]
    grey = crop.rgb[..., 0].astype(float)
    rows, cols = np.nonzero(grey > 0)
    weights = grey[rows, cols]
    centre = np.array([cols @ weights, rows @ weights]) / weights.sum()
    assert np.allclose(centre, moved, atol=0.1)  # a half-pixel slip would show


def test_hand_sources_compare_on_the_hands_both_found() -> None:
    """Two targets; one source finds both, the other one: the common set is that one hand."""
    from infinihand_ros.eval.matching import EvalFrame
    from infinihand_ros.eval.matching import HandPrediction
    from infinihand_ros.eval.matching import HandTarget
    from infinihand_ros.eval.metrics import camera_space_metrics
    from infinihand_ros.eval.metrics import match_frames
    from infinihand_ros.mano.builtin import canonical_joints
    import numpy as np

    sources = _benchmark('hand_sources_synthetic')
    intrinsics = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])

    def hand(kind: type, side: int, x: float, error_m: float = 0.0, **extra: object):
        joints = canonical_joints(side) - canonical_joints(side)[0] + [x, 0.0, 0.5]
        joints[1:] += error_m  # every joint but the wrist: root-relative error = error_m * sqrt(3)
        pixels = joints[:, :2] / joints[:, 2:] * 500.0 + [320, 240]
        return kind(side, joints, np.eye(3), np.r_[pixels.min(0), pixels.max(0)], **extra)

    targets = [hand(HandTarget, 0, -0.1), hand(HandTarget, 1, 0.1)]
    both = EvalFrame(intrinsics, 640, 480, targets,
                     [hand(HandPrediction, 0, -0.1, 0.01, score=0.9),
                      hand(HandPrediction, 1, 0.1, 0.01, score=0.9)])
    one = EvalFrame(intrinsics, 640, 480, targets, [hand(HandPrediction, 1, 0.1, 0.002,
                                                         score=0.9)])
    first, second = match_frames([both]), match_frames([one])
    common = [{t for t, _ in first[0].matched} & {t for t, _ in second[0].matched}]
    assert common == [{1}]
    for frame, matches, error in ((both, first, 0.01), (one, second, 0.002)):
        kept = sources._common_frames([frame], matches, common)
        assert [t.side for t in kept[0].targets] == [1] == [p.side for p in kept[0].predictions]
        figures = camera_space_metrics(kept)
        assert figures.num_missed == 0 and figures.num_matched == 1
        assert figures.mp_p_mm == pytest.approx(error * np.sqrt(3) * 1000 * 20 / 21)
