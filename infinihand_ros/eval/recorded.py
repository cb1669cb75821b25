"""Score a recorded live run of the estimator node against the bag's ground truth.

The recording (``record``) holds the node's ``~/camera_pose`` (PoseStamped ``T_world_cam``),
``~/hands/{left,right}/landmarks`` (PoseArray, 21 world joints; empty when the hand is not seen),
the replayed images and ``/diagnostics``. Outputs are aligned with the ground truth by header
stamp; a frame the node dropped has no result. The node publishes world joints only, so:

- camera-frame joints are recovered exactly as ``T_world_cam^-1`` of the published pose applied
  to the published world joints (the engine placed them with that very pose), and their boxes are
  the boxes of those joints projected with the ground truth's intrinsics (the bag's CameraInfo);
- a published hand counts as a positive prediction (the node publishes only the hands it keeps;
  it publishes no presence score);
- metrics that need what the node does not publish are left out (``MISSING_METRICS``).

Latency is receive time minus receive time, both taken by the recorder on one clock: the output
with a stamp against the replayed image with the same stamp.
"""

from collections.abc import Iterator
from dataclasses import dataclass
from dataclasses import fields
from dataclasses import replace
import math
from pathlib import Path
from typing import Any, Final

from infinihand_ros.bag.messages import msg_to_pose
from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.bag.reader import BagReader
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.topics import COMPRESSED_IMAGE_TOPIC
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.eval.matching import box_from_projection
from infinihand_ros.eval.runner import aggregate
from infinihand_ros.eval.runner import Evaluation
from infinihand_ros.eval.runner import Predictions
from infinihand_ros.eval.runner import score_sequence
from infinihand_ros.eval.sequences import EngineFrame
from infinihand_ros.eval.sequences import EvalSequence
from infinihand_ros.eval.sequences import GroundTruth
import numpy as np

DIAGNOSTICS_TOPIC: Final = '/diagnostics'
#: The estimator's status in /diagnostics is named '<node>: estimator'.
ESTIMATOR_STATUS_SUFFIX: Final = ': estimator'
#: Score given to a published hand (kept by the node; no presence score is published).
PUBLISHED_SCORE: Final = 1.0
NS_PER_MS: Final = 1e6
#: Metrics that need what the node does not publish, with the reason.
MISSING_METRICS: Final = {
    'FAcc': 'no presence score and no mesh box are published',
    'Recall': 'no presence score and no mesh box are published',
    'F1': 'no presence score and no mesh box are published',
    'GO-p': 'no global hand rotation (MANO) is published',
}


@dataclass(frozen=True)
class RecordedTopics:
    """Topic names of one recorded estimator node (absolute)."""

    camera_pose: str
    landmarks: tuple[str, str]
    image: str = COMPRESSED_IMAGE_TOPIC
    diagnostics: str = DIAGNOSTICS_TOPIC

    @classmethod
    def of_node(cls, node: str, image: str = COMPRESSED_IMAGE_TOPIC) -> 'RecordedTopics':
        """Return the topics of the node ``node`` (absolute, e.g. '/infinihand_estimator')."""
        return cls(f'{node}/camera_pose',
                   tuple(f'{node}/hands/{SIDE_NAMES[side]}/landmarks' for side in SIDES),
                   image)

    def names(self) -> list[str]:
        """Return every topic to record."""
        return [self.camera_pose, *self.landmarks, self.image, self.diagnostics]


@dataclass(frozen=True)
class RecordedRun:
    """What a recording holds, by image stamp (ns).

    Attributes:
        camera_poses: stamp -> (4, 4) published ``T_world_cam``.
        landmarks: per side (0 left, 1 right) stamp -> (21, 3) world joints, metres (stamps
            with an empty array are absent).
        output_times_ns: stamp -> receive time of its camera pose.
        input_times_ns: stamp -> receive time of the replayed image.
        diagnostics: key/value pairs of the last estimator status ({} when none came).

    """

    camera_poses: dict[int, np.ndarray]
    landmarks: tuple[dict[int, np.ndarray], dict[int, np.ndarray]]
    output_times_ns: dict[int, int]
    input_times_ns: dict[int, int]
    diagnostics: dict[str, str]


@dataclass(frozen=True)
class LiveFigures:
    """The node's figures in a live run.

    Attributes:
        images: images replayed.
        outputs: camera poses recorded.
        output_rate_hz: (outputs - 1) over the span of their receive times (0 with < 2).
        latency_p50_ms: median image-to-output receive latency, ms (NaN: no pair).
        latency_p95_ms: 95th percentile of that latency, ms (NaN: no pair).
        frames_received: images the node received (its last diagnostics).
        frames_dropped: images replaced before inference (input faster than the model).
        bad_frames: images or CameraInfos refused as malformed.
        not_received: replayed images that never reached the node.

    """

    images: int
    outputs: int
    output_rate_hz: float
    latency_p50_ms: float
    latency_p95_ms: float
    frames_received: int
    frames_dropped: int
    bad_frames: int
    not_received: int


def _points(msg: Any) -> np.ndarray:
    """Return the (N, 3) positions of a PoseArray."""
    return np.array([[p.position.x, p.position.y, p.position.z] for p in msg.poses],
                    dtype=np.float64).reshape(-1, 3)


def read_recorded(bag: str | Path, topics: RecordedTopics) -> RecordedRun:
    """Read a recording of ``topics`` (each must be in the bag; BagError naming it otherwise)."""
    poses: dict[int, np.ndarray] = {}
    landmarks: tuple[dict[int, np.ndarray], dict[int, np.ndarray]] = ({}, {})
    outputs: dict[int, int] = {}
    inputs: dict[int, int] = {}
    diagnostics: dict[str, str] = {}
    with BagReader(bag) as reader:
        for topic, log_time, msg in reader.messages(topics.names()):
            if topic == topics.diagnostics:
                for status in msg.status:
                    if status.name.endswith(ESTIMATOR_STATUS_SUFFIX):
                        diagnostics = {kv.key: kv.value for kv in status.values}
                continue
            stamp = ns_from_stamp(msg.header.stamp)
            if topic == topics.image:
                inputs.setdefault(stamp, log_time)
            elif topic == topics.camera_pose:
                poses[stamp] = msg_to_pose(msg.pose).matrix()
                outputs.setdefault(stamp, log_time)
            elif len(msg.poses):
                landmarks[topics.landmarks.index(topic)][stamp] = _points(msg)
    return RecordedRun(poses, landmarks, outputs, inputs, diagnostics)


def output_rate_hz(run: RecordedRun) -> float:
    """Return the recorded output rate, Hz (see ``LiveFigures.output_rate_hz``)."""
    times = sorted(run.output_times_ns.values())
    span_s = (times[-1] - times[0]) / NS_PER_S if len(times) > 1 else 0.0
    return (len(times) - 1) / span_s if span_s > 0 else 0.0


def live_figures(run: RecordedRun, images: int) -> LiveFigures:
    """Return the figures of a run in which ``images`` images were replayed."""
    latency_ms = [(out - run.input_times_ns[stamp]) / NS_PER_MS
                  for stamp, out in run.output_times_ns.items() if stamp in run.input_times_ns]
    p50, p95 = (np.percentile(latency_ms, [50.0, 95.0]) if latency_ms
                else (math.nan, math.nan))
    values = run.diagnostics
    received = int(values.get('frames_received', 0))
    return LiveFigures(images, len(run.camera_poses), output_rate_hz(run), float(p50),
                       float(p95), received, int(values.get('frames_dropped', 0)),
                       int(values.get('bad_frames', 0)), images - received)


def segment(sequence: EvalSequence, stamps: set[int]) -> EvalSequence:
    """Return ``sequence`` restricted to its frames with these image stamps (the replayed ones)."""
    keep = np.array([int(stamp) in stamps for stamp in sequence.truth.timestamp_ns], bool)
    truth = GroundTruth(**{item.name: getattr(sequence.truth, item.name)[keep]
                           for item in fields(GroundTruth)})

    def frames() -> Iterator[EngineFrame]:
        return (frame for frame in sequence.frames() if frame[1] in stamps)

    return replace(sequence, truth=truth, frames=frames)


def recorded_predictions(run: RecordedRun, sequence: EvalSequence) -> Predictions:
    """Return the run's outputs as the runner's predictions, aligned with ``sequence``'s frames."""
    truth = sequence.truth
    out = Predictions.empty(truth.timestamp_ns, output_rate_hz(run))
    for row, stamp in enumerate(int(s) for s in truth.timestamp_ns):
        T_world_cam = run.camera_poses.get(stamp)
        if T_world_cam is None:
            continue
        out.has_result[row] = True
        out.T_world_cam[row] = T_world_cam
        T_cam_world = np.linalg.inv(T_world_cam)
        for side in SIDES:
            joints_world = run.landmarks[side].get(stamp)
            if joints_world is None or joints_world.shape != (NUM_JOINTS, 3):
                continue
            joints_cam = joints_world @ T_cam_world[:3, :3].T + T_cam_world[:3, 3]
            out.hand_valid[row, side] = True
            out.confidence[row, side] = PUBLISHED_SCORE
            out.joints_world[row, side] = joints_world
            out.joints_cam[row, side] = joints_cam
            out.box_xyxy[row, side] = box_from_projection(joints_cam, truth.K[row])
    return out


def evaluate_recorded(run: RecordedRun, sequence: EvalSequence, mean_pose_joints: np.ndarray
                      ) -> Evaluation:
    """Score the run on ``sequence`` (the runner's rules).

    ``MISSING_METRICS`` become NaN, and there is no detection breakdown (detection is among them).
    """
    evaluation = aggregate([score_sequence(sequence, recorded_predictions(run, sequence),
                                           mean_pose_joints)])
    ours = {key: math.nan if key in MISSING_METRICS else value
            for key, value in evaluation.ours.items()}
    return replace(evaluation, ours=ours, detection=None)


def missing_note() -> str:
    """Return the lines that say which metrics are left out and why."""
    reasons: dict[str, list[str]] = {}
    for metric, reason in MISSING_METRICS.items():
        reasons.setdefault(reason, []).append(metric)
    return '\n'.join(f'- not computed: {", ".join(metrics)} ({reason})'
                     for reason, metrics in reasons.items())
