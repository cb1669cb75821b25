"""Recorded live runs scored against ground truth (eval/recorded.py), on a hand-written bag."""

from pathlib import Path
from typing import Any

from infinihand_ros.bag.messages import pose_to_msg
from infinihand_ros.bag.messages import stamp_from_ns
from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.bag.typestore import COMPRESSED_IMAGE_MSG
from infinihand_ros.bag.typestore import HEADER_MSG
from infinihand_ros.bag.typestore import POSE_STAMPED_MSG
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.eval import baselines
from infinihand_ros.eval.matching import box_from_projection
from infinihand_ros.eval.recorded import evaluate_recorded
from infinihand_ros.eval.recorded import live_figures
from infinihand_ros.eval.recorded import MISSING_METRICS
from infinihand_ros.eval.recorded import missing_note
from infinihand_ros.eval.recorded import read_recorded
from infinihand_ros.eval.recorded import recorded_predictions
from infinihand_ros.eval.recorded import RecordedTopics
from infinihand_ros.eval.recorded import segment
from infinihand_ros.eval.sequences import EvalSequence
from infinihand_ros.eval.sequences import open_eval_sequence
from infinihand_ros.synth.cli import generate
from infinihand_ros.synth.sequence import SynthConfig
import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer
from rosbags.typesys.store import Typestore

FRAMES = 8
DROPPED = 3
#: Receive times: an image at 1 s + row * 0.1 s, its camera pose 40 ms later.
IMAGE_AT_NS = 1_000_000_000
PERIOD_NS = 100_000_000
LATENCY_NS = 40_000_000
TOPICS = RecordedTopics.of_node('/infinihand_estimator')
DIAGNOSTICS = {'frames_received': str(FRAMES), 'frames_dropped': '1', 'bad_frames': '0'}


@pytest.fixture(scope='module')
def sequence(tmp_path_factory: pytest.TempPathFactory) -> EvalSequence:
    """Return a short synthetic bag with ground truth (10 FPS, 160 x 120), opened for eval."""
    out = tmp_path_factory.mktemp('recorded') / 'seq_5'
    generate(SynthConfig(fps=10.0, width=160, height=120), seed=5, frames=FRAMES, out=out,
             progress=False)
    return open_eval_sequence(out / 'bag')


def _header(store: Typestore, stamp_ns: int) -> Any:
    return store.types[HEADER_MSG](stamp=stamp_from_ns(store, stamp_ns), frame_id='world')


def _pose_array(store: Typestore, stamp_ns: int, joints: np.ndarray | None) -> Any:
    types = store.types
    poses = [] if joints is None else [
        types['geometry_msgs/msg/Pose'](
            position=types['geometry_msgs/msg/Point'](x=float(x), y=float(y), z=float(z)),
            orientation=types['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0))
        for x, y, z in joints]
    return types['geometry_msgs/msg/PoseArray'](header=_header(store, stamp_ns), poses=poses)


def _diagnostics(store: Typestore, stamp_ns: int) -> Any:
    types = store.types
    status = types['diagnostic_msgs/msg/DiagnosticStatus'](
        level=0, name='infinihand_estimator: estimator', message='running', hardware_id='',
        values=[types['diagnostic_msgs/msg/KeyValue'](key=k, value=v)
                for k, v in DIAGNOSTICS.items()])
    return types['diagnostic_msgs/msg/DiagnosticArray'](header=_header(store, stamp_ns),
                                                        status=[status])


def _write_recording(path: Path, sequence: EvalSequence) -> None:
    """Write what a perfect node would publish, except frame ``DROPPED`` (no output)."""
    store = build_typestore()
    truth = sequence.truth
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {topic: writer.add_connection(topic, msgtype, typestore=store) for topic, msgtype
                 in [(TOPICS.image, COMPRESSED_IMAGE_MSG), (TOPICS.camera_pose, POSE_STAMPED_MSG),
                     *((t, 'geometry_msgs/msg/PoseArray') for t in TOPICS.landmarks),
                     (TOPICS.diagnostics, 'diagnostic_msgs/msg/DiagnosticArray')]}

        def write(topic: str, time_ns: int, msg: Any) -> None:
            writer.write(conns[topic], time_ns, store.serialize_cdr(msg, msg.__msgtype__))

        for row, stamp in enumerate(int(s) for s in truth.timestamp_ns):
            at = IMAGE_AT_NS + row * PERIOD_NS
            write(TOPICS.image, at, store.types[COMPRESSED_IMAGE_MSG](
                header=_header(store, stamp), format='jpeg', data=np.zeros(0, np.uint8)))
            if row == DROPPED:
                continue
            pose = CameraPose.from_matrix(truth.T_world_cam[row])
            write(TOPICS.camera_pose, at + LATENCY_NS, store.types[POSE_STAMPED_MSG](
                header=_header(store, stamp), pose=pose_to_msg(store, pose)))
            for side in SIDES:
                joints = truth.joints_world[row, side] if truth.visible[row, side] else None
                write(TOPICS.landmarks[side], at + LATENCY_NS, _pose_array(store, stamp, joints))
        write(TOPICS.diagnostics, at + PERIOD_NS, _diagnostics(store, stamp))


def test_recording_reads_back_by_stamp(sequence: EvalSequence, tmp_path: Path) -> None:
    """Poses, non-empty landmark arrays, receive times and the last estimator status."""
    _write_recording(tmp_path / 'rec', sequence)
    run = read_recorded(tmp_path / 'rec', TOPICS)
    truth = sequence.truth
    stamps = [int(s) for s in truth.timestamp_ns]
    assert sorted(run.camera_poses) == [s for row, s in enumerate(stamps) if row != DROPPED]
    assert len(run.input_times_ns) == FRAMES
    for side in SIDES:
        seen = {s for row, s in enumerate(stamps) if truth.visible[row, side] and row != DROPPED}
        assert set(run.landmarks[side]) == seen
    np.testing.assert_allclose(run.camera_poses[stamps[1]], truth.T_world_cam[1], atol=1e-9)
    assert run.diagnostics == DIAGNOSTICS
    figures = live_figures(run, FRAMES + 2)
    assert figures.latency_p50_ms == pytest.approx(40.0)
    assert figures.latency_p95_ms == pytest.approx(40.0)
    assert figures.outputs == FRAMES - 1
    assert figures.output_rate_hz == pytest.approx((FRAMES - 2) / ((FRAMES - 1) * 0.1))
    assert (figures.frames_dropped, figures.not_received) == (1, 2)


def test_predictions_recover_camera_joints_and_miss_dropped_frames(
        sequence: EvalSequence, tmp_path: Path) -> None:
    """The published pose maps world joints back to the truth's camera joints exactly."""
    _write_recording(tmp_path / 'rec', sequence)
    pred = recorded_predictions(read_recorded(tmp_path / 'rec', TOPICS), sequence)
    truth = sequence.truth
    assert pred.has_result.tolist() == [row != DROPPED for row in range(FRAMES)]
    expected_valid = truth.visible.copy()
    expected_valid[DROPPED] = False
    np.testing.assert_array_equal(pred.hand_valid, expected_valid)
    assert expected_valid.any()
    np.testing.assert_allclose(pred.joints_cam[expected_valid], truth.joints_cam[expected_valid],
                               atol=1e-9)
    row, side = np.argwhere(expected_valid)[0]
    np.testing.assert_allclose(pred.box_xyxy[row, side],
                               box_from_projection(truth.joints_cam[row, side], truth.K[row]))
    assert np.isnan(pred.T_world_cam[DROPPED]).all()


def test_evaluation_scores_what_is_published_and_leaves_out_the_rest(
        sequence: EvalSequence, tmp_path: Path) -> None:
    """Perfect outputs score zero; the dropped frame's hands are misses; detection is left out."""
    _write_recording(tmp_path / 'rec', sequence)
    run = read_recorded(tmp_path / 'rec', TOPICS)
    mean_pose = baselines.mean_pose_joints(np.zeros((15, 3)))
    evaluation = evaluate_recorded(run, sequence, mean_pose)
    assert evaluation.detection is None  # no per-side recall where Recall is not computed
    ours = evaluation.ours
    for name in ('W-MPJPE', 'PA-MPJPE', 'WA-MPJPE', 'ATE'):
        assert ours[name] == pytest.approx(0.0, abs=1e-6), name
    assert sequence.truth.visible[DROPPED].any() and ours['MP-p'] > 1.0  # missed, penalised
    assert all(np.isnan(ours[name]) for name in MISSING_METRICS)
    published = {int(s) for row, s in enumerate(sequence.truth.timestamp_ns) if row != DROPPED}
    ours = evaluate_recorded(run, segment(sequence, published), mean_pose).ours
    for name in ('MP-p', 'PA-p', 'EPE-p', 'CT-p'):
        assert ours[name] == pytest.approx(0.0, abs=1e-6), name
    assert 'not computed: FAcc, Recall, F1' in missing_note() and 'GO-p' in missing_note()


def test_segment_keeps_the_replayed_frames(sequence: EvalSequence) -> None:
    """Only the frames whose stamps were replayed stay, in order, with their images."""
    stamps = {int(s) for s in sequence.truth.timestamp_ns[:3]}
    part = segment(sequence, stamps)
    assert part.truth.num_frames == 3 and part.truth.joints_world.shape[0] == 3
    assert [frame[1] for frame in part.frames()] == sorted(stamps)
