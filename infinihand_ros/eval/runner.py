"""Run the streaming engine over held-out sequences and score it beside the baselines.

Per sequence: every frame goes through one ``StreamingEngine`` (with the sequence's intrinsics
when it has them, as the node has CameraInfo); by default the trajectory known at the end is
scored (BA-refined when BA runs, as the paper places world-space hands with the refined poses),
or with ``poses='live'`` each frame as it was published; the results are matched to the ground
truth by stamp; appendix A's matching (``eval.matching``) decides which predicted hand answers
which target. Ours and every baseline are then scored on exactly those matched hand-frame pairs:
world-space W-MPJPE, PA-MPJPE, WA-MPJPE per sequence, the camera's ATE and RPE per sequence
(``static-camera`` holds our first pose), detection and camera-space metrics over the frames.
Across sequences, detection and camera-space metrics pool every frame; world-space and camera
metrics are the mean of the per-sequence values (every sequence weighs the same).
"""

from collections.abc import Callable
from collections.abc import Sequence
from dataclasses import dataclass
import time

from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.geometry import axis_angle_to_matrix
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.eval import baselines
from infinihand_ros.eval.detection_breakdown import detection_breakdown
from infinihand_ros.eval.detection_breakdown import DetectionBreakdown
from infinihand_ros.eval.matching import EvalFrame
from infinihand_ros.eval.matching import HandPrediction
from infinihand_ros.eval.matching import HandTarget
from infinihand_ros.eval.metrics import camera_space_metrics
from infinihand_ros.eval.metrics import detection_metrics
from infinihand_ros.eval.metrics import match_frames
from infinihand_ros.eval.metrics import world_space
from infinihand_ros.eval.sequences import EvalSequence
from infinihand_ros.eval.trajectory import trajectory_metrics
import numpy as np

Metrics = dict[str, float]
#: Which poses are scored: as published per frame, or the trajectory known at the end.
POSES = ('live', 'final')


@dataclass(frozen=True)
class Predictions:
    """What the engine said about one sequence, aligned with its ground-truth frames.

    Attributes:
        timestamp_ns: (T,) the ground truth's stamps.
        has_result: (T,) bool, the engine returned a result for the frame.
        T_world_cam: (T, 4, 4) predicted camera-to-world (NaN without a result).
        hand_valid: (T, 2) bool, a hand of that side was predicted.
        confidence: (T, 2) presence scores (0 where none).
        joints_cam: (T, 2, 21, 3) camera-frame joints (NaN where none).
        joints_world: (T, 2, 21, 3) world joints (NaN where none).
        rotation_cam: (T, 2, 3, 3) camera-frame hand rotations (identity where none).
        box_xyxy: (T, 2, 4) boxes in source pixels.
        frames_per_s: engine throughput over the sequence (frames / wall second).

    """

    timestamp_ns: np.ndarray
    has_result: np.ndarray
    T_world_cam: np.ndarray
    hand_valid: np.ndarray
    confidence: np.ndarray
    joints_cam: np.ndarray
    joints_world: np.ndarray
    rotation_cam: np.ndarray
    box_xyxy: np.ndarray
    frames_per_s: float

    @staticmethod
    def empty(timestamp_ns: np.ndarray, frames_per_s: float) -> 'Predictions':
        """Return predictions for these stamps with no result and no hand yet (filled in place)."""
        count = len(timestamp_ns)
        return Predictions(
            timestamp_ns=np.array(timestamp_ns, dtype=np.int64), has_result=np.zeros(count, bool),
            T_world_cam=np.full((count, 4, 4), np.nan), hand_valid=np.zeros((count, 2), bool),
            confidence=np.zeros((count, 2)),
            joints_cam=np.full((count, 2, NUM_JOINTS, 3), np.nan),
            joints_world=np.full((count, 2, NUM_JOINTS, 3), np.nan),
            rotation_cam=np.tile(np.eye(3), (count, 2, 1, 1)), box_xyxy=np.zeros((count, 2, 4)),
            frames_per_s=frames_per_s)


@dataclass(frozen=True)
class SequenceEvaluation:
    """Scores of one sequence.

    Attributes:
        name: the sequence's name.
        num_frames: ground-truth frames.
        fps: the sequence's frame rate (Hz).
        frames: the matched ``EvalFrame`` list (pooled across sequences).
        ours: world-space and camera metrics of our predictions.
        baselines: the same metrics per baseline (those that apply to it).
        matched: (T, 2) bool, the hand-frame pairs every world-space metric is computed on.
        predictions: the engine's outputs.

    """

    name: str
    num_frames: int
    fps: float
    frames: list[EvalFrame]
    ours: Metrics
    baselines: dict[str, Metrics]
    matched: np.ndarray
    predictions: Predictions


def run_engine(sequence: EvalSequence, engine: StreamingEngine,
               poses: str = 'final') -> Predictions:
    """Stream every frame of ``sequence`` through ``engine`` and collect its results.

    ``poses`` (``POSES``): ``live`` scores each frame as the engine published it; ``final``
    scores the trajectory known at the end (``StreamingEngine.refined``: every BA correction
    and the final metric scale), as an offline run uses it. The throughput counts both.
    """
    if poses not in POSES:
        raise ValueError(f'poses: expected one of {POSES}, got {poses!r}')
    results: list[FrameResult] = []
    start = time.perf_counter()
    for rgb, stamp, intrinsics in sequence.frames():
        results.extend(engine.push(rgb, stamp, intrinsics))
    results.extend(engine.flush())
    if poses == 'final':
        results = engine.refined(results)
    seconds = time.perf_counter() - start
    truth = sequence.truth
    rows = {int(stamp): row for row, stamp in enumerate(truth.timestamp_ns)}
    out = Predictions.empty(truth.timestamp_ns, len(results) / max(seconds, 1e-9))
    for result in results:
        row = rows.get(result.timestamp_ns)
        if row is None:
            continue
        out.has_result[row] = True
        out.T_world_cam[row] = result.camera_pose.matrix()
        for hand in sorted(result.hands, key=lambda h: h.confidence):  # best one per side last
            side = hand.side
            out.hand_valid[row, side] = True
            out.confidence[row, side] = hand.confidence
            out.joints_cam[row, side] = hand.joints_cam
            if hand.joints_world is not None:
                out.joints_world[row, side] = hand.joints_world
            out.rotation_cam[row, side] = axis_angle_to_matrix(hand.mano_cam.global_orient)
            out.box_xyxy[row, side] = hand.box_xyxy
    return out


def eval_frames(sequence: EvalSequence, pred: Predictions) -> list[EvalFrame]:
    """Return the appendix-A frames: visible ground-truth hands against predicted hands."""
    truth = sequence.truth
    frames = []
    for row in range(truth.num_frames):
        targets = [HandTarget(side, truth.joints_cam[row, side], truth.rotation_cam[row, side],
                              truth.box_xyxy[row, side])
                   for side in SIDES if truth.visible[row, side]]
        predictions = [HandPrediction(side, pred.joints_cam[row, side],
                                      pred.rotation_cam[row, side], pred.box_xyxy[row, side],
                                      float(pred.confidence[row, side]))
                       for side in SIDES if pred.hand_valid[row, side]]
        frames.append(EvalFrame(truth.K[row], sequence.width, sequence.height, targets,
                                predictions))
    return frames


def matched_pairs(frames: Sequence[EvalFrame]) -> np.ndarray:
    """Return (T, 2) bool: the side's target was matched to a prediction in that frame."""
    out = np.zeros((len(frames), len(SIDES)), bool)
    for row, (frame, match) in enumerate(zip(frames, match_frames(frames))):
        for target, _ in match.matched:
            out[row, frame.targets[target].side] = True
    return out


def scored_pairs(frames: Sequence[EvalFrame], pred: Predictions) -> np.ndarray:
    """Return (T, 2) bool: the hand-frame pairs every world-space figure is scored on.

    A side's target was matched in ``frames`` (appendix A) and our hand was placed in the world.
    """
    placed = np.isfinite(pred.joints_world).all(axis=(-2, -1))
    return matched_pairs(frames) & placed & pred.has_result[:, None]


def _world(pred_joints: np.ndarray, gt_joints: np.ndarray, pairs: np.ndarray) -> Metrics:
    """World-space metrics, NaN when no pair is scored."""
    if not pairs.any():
        return {'W-MPJPE': float('nan'), 'PA-MPJPE': float('nan'), 'WA-MPJPE': float('nan')}
    return world_space(pred_joints, gt_joints, pairs)


def score_sequence(sequence: EvalSequence, pred: Predictions,
                   mean_pose_joints: np.ndarray) -> SequenceEvaluation:
    """Score ``pred`` and the baselines on ``sequence`` (see the module docstring)."""
    truth = sequence.truth
    frames = eval_frames(sequence, pred)
    pairs = scored_pairs(frames, pred)
    posed = pred.has_result
    ours = _world(pred.joints_world, truth.joints_world, pairs)
    first_pose = pred.T_world_cam[np.argmax(posed)]
    static_T = np.broadcast_to(first_pose, pred.T_world_cam.shape)
    static = _world(baselines.static_camera_joints(pred.joints_cam, first_pose),
                    truth.joints_world, pairs)
    if posed.sum() > 1:
        ours.update(trajectory_metrics(pred.T_world_cam[posed], truth.T_world_cam[posed])
                    .as_dict())
        static.update(trajectory_metrics(static_T[posed], truth.T_world_cam[posed]).as_dict())
    mean_hand = _world(baselines.mean_hand_joints(truth.joints_world, truth.visible),
                       truth.joints_world, pairs)
    mean_pose = _world(baselines.mean_pose_world_joints(mean_pose_joints, truth.num_frames),
                       truth.joints_world, pairs)
    return SequenceEvaluation(
        name=sequence.name, num_frames=truth.num_frames, fps=sequence.fps, frames=frames,
        ours=ours, baselines={'static-camera': static, 'mean-hand': mean_hand,
                              'mean-pose': {'PA-MPJPE': mean_pose['PA-MPJPE']}},
        matched=pairs, predictions=pred)


def _mean(values: list[Metrics]) -> Metrics:
    """Per-key mean over sequences, skipping NaN (NaN when no sequence has the key)."""
    keys = dict.fromkeys(key for metrics in values for key in metrics)
    out = {}
    for key in keys:
        finite = [m[key] for m in values if key in m and np.isfinite(m[key])]
        out[key] = float(np.mean(finite)) if finite else float('nan')
    return out


@dataclass(frozen=True)
class Evaluation:
    """Scores of a run over all sequences.

    Attributes:
        ours: pooled detection and camera-space metrics, mean world-space and camera metrics,
            the engine's mean throughput (``frames/s``).
        baselines: mean metrics per baseline.
        sequences: the per-sequence evaluations.
        detection: where detection failed (by side, size, miss cause), None without targets.

    """

    ours: Metrics
    baselines: dict[str, Metrics]
    sequences: list[SequenceEvaluation]
    detection: DetectionBreakdown | None = None


def aggregate(evaluations: list[SequenceEvaluation]) -> Evaluation:
    """Pool and average per-sequence evaluations (see the module docstring)."""
    frames = [frame for evaluation in evaluations for frame in evaluation.frames]
    ours: Metrics = {}
    breakdown = None
    if any(frame.targets for frame in frames):
        matches = match_frames(frames)
        ours.update(detection_metrics(frames, matches).as_dict())
        ours.update(camera_space_metrics(frames, matches=matches).as_dict())
        breakdown = detection_breakdown(frames, matches)
    ours.update(_mean([e.ours for e in evaluations]))
    ours['frames/s'] = float(np.mean([e.predictions.frames_per_s for e in evaluations]))
    names = dict.fromkeys(name for e in evaluations for name in e.baselines)
    return Evaluation(ours=ours,
                      baselines={name: _mean([e.baselines[name] for e in evaluations])
                                 for name in names},
                      sequences=evaluations, detection=breakdown)


def evaluate(sequences: Sequence[EvalSequence], make_engine: Callable[[], StreamingEngine],
             mean_pose_joints: np.ndarray,
             on_sequence: Callable[[SequenceEvaluation], None] | None = None,
             poses: str = 'final') -> Evaluation:
    """Run a fresh engine over every sequence, score each (``poses``: see ``run_engine``)."""
    evaluations = []
    for sequence in sequences:
        with make_engine() as engine:
            pred = run_engine(sequence, engine, poses)
        evaluation = score_sequence(sequence, pred, mean_pose_joints)
        evaluations.append(evaluation)
        if on_sequence is not None:
            on_sequence(evaluation)
    return aggregate(evaluations)
