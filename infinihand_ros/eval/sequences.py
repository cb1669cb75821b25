"""Held-out sequences for the evaluation: their frames and their ground truth, whatever the source.

Two sources hold ground truth: a sample directory (``data/sample_format.py``, the synthetic
generator's ``samples/``; a generator output folder is accepted for its ``samples/``), read with
the training reader (``train.sequence_reader.open_sequence``); and a rosbag2 bag with the
ground-truth topics (``core/topics.py``: ``/ground_truth/hands`` HandFrame messages, whose camera
pose and intrinsics are the truth too), read with ``bag/``. Both give a ``GroundTruth`` of
per-frame arrays (side axis [left, right]) and a frame iterator for the engine. A sample
directory's lens (``meta.json`` ``sequence.distortion_model`` and ``distortion``) and a bag's
CameraInfo distortion go to the engine with the intrinsics.
"""

from collections.abc import Callable
from collections.abc import Iterator
from dataclasses import dataclass
from dataclasses import replace
from pathlib import Path

from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.bag.messages import msg_to_frame_result
from infinihand_ros.bag.reader import BagReader
from infinihand_ros.core import topics
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.distortion import check_distortion
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import axis_angle_to_matrix
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.corpus import sample_format as fmt
from infinihand_ros.train.sequence_reader import open_sequence
import numpy as np

#: A frame for the engine: RGB (H, W, 3) uint8, stamp (ns), intrinsics (None: predicted).
EngineFrame = tuple[np.ndarray, int, Intrinsics | None]
#: The folder of a generator output that holds its sample directory.
SAMPLES_SUBDIR = 'samples'


@dataclass(frozen=True)
class GroundTruth:
    """Per-frame ground truth of a sequence (T frames, side axis [left, right]).

    Attributes:
        timestamp_ns: (T,) image stamps.
        K: (T, 3, 3) intrinsics, pixels.
        T_world_cam: (T, 4, 4) camera-to-world (world = first camera).
        visible: (T, 2) bool, the hand is annotated and visible (a target of the metrics).
        joints_cam: (T, 2, 21, 3) camera-frame joints (m).
        joints_world: (T, 2, 21, 3) world joints (m).
        rotation_cam: (T, 2, 3, 3) camera-frame global hand rotation.
        box_xyxy: (T, 2, 4) pixel boxes.
        hand_pose: (T, 2, 15, 3) MANO articulation (NaN where unknown).

    """

    timestamp_ns: np.ndarray
    K: np.ndarray
    T_world_cam: np.ndarray
    visible: np.ndarray
    joints_cam: np.ndarray
    joints_world: np.ndarray
    rotation_cam: np.ndarray
    box_xyxy: np.ndarray
    hand_pose: np.ndarray

    @property
    def num_frames(self) -> int:
        """Return T."""
        return len(self.timestamp_ns)


@dataclass(frozen=True)
class EvalSequence:
    """One held-out sequence.

    Attributes:
        name: a short name (the directory's), used for file names and the report.
        path: where it was read from.
        width: image width (px).
        height: image height (px).
        truth: its ground truth.
        frames: returns a fresh iterator over the frames in order (one per ground-truth frame).

    """

    name: str
    path: Path
    width: int
    height: int
    truth: GroundTruth
    frames: Callable[[], Iterator[EngineFrame]]

    @property
    def fps(self) -> float:
        """Return the frame rate from the stamps (Hz)."""
        stamps = self.truth.timestamp_ns
        if len(stamps) < 2:
            return 0.0
        return float((len(stamps) - 1) * 1e9 / (stamps[-1] - stamps[0]))


def _sample_sequence(root: Path, name: str) -> EvalSequence:
    """Read a sample directory."""
    reader = open_sequence(root)
    arrays = reader.annotations()
    try:
        orient = arrays['mano_cam_global_orient']
        truth = GroundTruth(
            timestamp_ns=arrays['timestamp_ns'].astype(np.int64), K=arrays['K'],
            T_world_cam=arrays['T_world_cam'],
            visible=arrays['hand_present'].astype(bool) & arrays['visible'].astype(bool),
            joints_cam=arrays['joints_cam'], joints_world=arrays['joints_world'],
            rotation_cam=axis_angle_to_matrix(orient.reshape(-1, 3)).reshape(
                *orient.shape[:2], 3, 3),
            box_xyxy=arrays['box_xyxy'], hand_pose=arrays['mano_cam_hand_pose'])
    except KeyError as exc:
        raise InputError(f'{root / fmt.ANNOTATIONS_FILE}: no {exc} array; the evaluation needs '
                         'the full ground truth of the sample format') from exc
    width, height = reader.image_size
    lens = fmt.read_meta(root).get('sequence') or {}
    model, coefficients = check_distortion(lens.get('distortion_model'), lens.get('distortion'),
                                           f'{root / fmt.META_FILE} sequence lens')

    def frames() -> Iterator[EngineFrame]:
        for index in range(reader.num_frames):
            K = truth.K[index]
            intrinsics = Intrinsics.from_matrix(K, width, height)
            yield (reader.read_rgb(index), int(truth.timestamp_ns[index]),
                   replace(intrinsics, distortion_model=model, distortion=coefficients))

    return EvalSequence(name, root, width, height, truth, frames)


def _bag_sequence(path: Path, name: str) -> EvalSequence:
    """Read a bag with the ground-truth topics."""
    with BagReader(path) as reader:
        if topics.GT_HANDS_TOPIC not in reader.topics():
            raise InputError(f'{path}: no {topics.GT_HANDS_TOPIC} topic; the evaluation needs a '
                             'bag with ground truth (e.g. python -m infinihand_ros.synth)')
        results = [msg_to_frame_result(msg)
                   for _, _, msg in reader.messages([topics.GT_HANDS_TOPIC])]
    if not results:
        raise InputError(f'{path}: {topics.GT_HANDS_TOPIC} holds no message')
    count = len(results)
    truth = GroundTruth(
        timestamp_ns=np.array([r.timestamp_ns for r in results], np.int64),
        K=np.stack([r.intrinsics.matrix() for r in results]),
        T_world_cam=np.stack([r.camera_pose.matrix() for r in results]),
        visible=np.zeros((count, 2), bool), joints_cam=np.full((count, 2, NUM_JOINTS, 3), np.nan),
        joints_world=np.full((count, 2, NUM_JOINTS, 3), np.nan),
        rotation_cam=np.tile(np.eye(3), (count, 2, 1, 1)), box_xyxy=np.zeros((count, 2, 4)),
        hand_pose=np.full((count, 2, 15, 3), np.nan))
    for row, result in enumerate(results):
        for hand in result.hands:
            side = hand.side
            truth.visible[row, side] = hand.confidence > 0.5 and hand.joints_world is not None
            truth.joints_cam[row, side] = hand.joints_cam
            if hand.joints_world is not None:
                truth.joints_world[row, side] = hand.joints_world
            truth.rotation_cam[row, side] = axis_angle_to_matrix(hand.mano_cam.global_orient)
            truth.box_xyxy[row, side] = hand.box_xyxy
            truth.hand_pose[row, side] = hand.mano_cam.hand_pose.reshape(15, 3)
    width, height = results[0].intrinsics.width, results[0].intrinsics.height
    by_stamp = {int(stamp): row for row, stamp in enumerate(truth.timestamp_ns)}

    def frames() -> Iterator[EngineFrame]:
        seen = 0
        for frame in read_camera_frames(path):
            if frame.timestamp_ns in by_stamp:
                seen += 1
                yield frame.rgb, frame.timestamp_ns, frame.intrinsics
        if seen != count:
            raise InputError(f'{path}: {count} ground-truth frames but {seen} images with '
                             'the same stamps')

    return EvalSequence(name, path, width, height, truth, frames)


def open_eval_sequence(path: str | Path) -> EvalSequence:
    """Open a sample directory, a generator output folder or a bag with ground truth.

    Raises:
        InputError: naming the path when it is none of those or its ground truth is incomplete.

    """
    path = Path(path)
    if not path.exists():
        raise InputError(f'--sequences {path}: no such file or directory')
    name = path.name if path.name not in (SAMPLES_SUBDIR, 'bag') else path.parent.name
    if (path / fmt.META_FILE).is_file():
        return _sample_sequence(path, name)
    if (path / SAMPLES_SUBDIR / fmt.META_FILE).is_file():
        return _sample_sequence(path / SAMPLES_SUBDIR, name)
    if (path / 'metadata.yaml').is_file() or path.suffix in ('.mcap', '.db3', '.bag'):
        return _bag_sequence(path, name)
    raise InputError(f'--sequences {path}: not a sample directory (meta.json), a generator '
                     'output folder (samples/meta.json) or a rosbag2 bag (metadata.yaml)')
