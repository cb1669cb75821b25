"""Adapter of our bag converter's output (LeRobot v3.0 datasets written by ``bag_to_dataset``).

Layout (``convert/lerobot_layout.py``, LeRobot v0.4 ``datasets/utils.py``): ``meta/info.json``
(fps, ``data_path`` / ``video_path`` templates, features), ``meta/episodes/chunk-*/file-*.parquet``
(one row per episode: its data and video files and the video's ``from_timestamp``), data parquet
files with one row per frame, and one mp4 per video file. Features are ours
(``convert/lerobot_features.py``): ``camera.T_world_cam`` (row-major 4x4, OpenCV optical camera,
world = the episode's first anchor camera), ``camera.intrinsics`` (fx, fy, cx, cy),
``hands.valid`` and ``hands.keypoints_world`` (left then right, 21 OpenPose joints, metres).

The hands are the estimator's own outputs, not ground truth: such sequences adapt a model to a
user's camera and hands (self-training) and should be cleaned against an independent 2D source.
MANO is re-fitted to the joints so that it matches the configured hand model.
"""

from collections.abc import Iterator
import json
from pathlib import Path
from typing import Final

from infinihand_ros.convert import lerobot_features as feat
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.corpus.adapters.frames import VideoFrames
from infinihand_ros.corpus.sequence import CorpusSequence
import numpy as np
import pyarrow.parquet as pq

SOURCE: Final = 'infinihand-bags'
LICENCE: Final = "the recording owner's"
INFO_FILE: Final = 'meta/info.json'
EPISODES_GLOB: Final = 'meta/episodes/chunk-*/file-*.parquet'


def _matrix(table: dict, key: str, columns: int) -> np.ndarray:
    """Return a feature column as (N, columns) float64."""
    return np.asarray(table[key], np.float64).reshape(-1, columns)


def _episode(root: Path, info: dict, row: dict, video_key: str) -> CorpusSequence:
    data_file = root / info['data_path'].format(chunk_index=row['data/chunk_index'],
                                                file_index=row['data/file_index'])
    table = pq.read_table(data_file).to_pydict()
    keep = np.asarray(table[feat.EPISODE_INDEX]) == row['episode_index']
    table = {key: [v for v, k in zip(values, keep) if k] for key, values in table.items()}
    frames = int(keep.sum())
    T_world_cam = _matrix(table, feat.CAMERA_POSE, 16).reshape(frames, 4, 4)
    fx, fy, cx, cy = _matrix(table, feat.INTRINSICS, 4).T
    K = np.zeros((frames, 3, 3))
    K[:, 0, 0], K[:, 1, 1], K[:, 0, 2], K[:, 1, 2], K[:, 2, 2] = fx, fy, cx, cy, 1.0
    present = _matrix(table, feat.HAND_VALID, len(SIDES)) > 0.5
    world = _matrix(table, feat.KEYPOINTS_WORLD, 2 * NUM_JOINTS * 3).reshape(
        frames, len(SIDES), NUM_JOINTS, 3)
    T_cam_world = np.linalg.inv(T_world_cam)
    joints = np.einsum('tij,tsnj->tsni', T_cam_world[:, :3, :3], world) \
        + T_cam_world[:, None, None, :3, 3]
    joints = np.where(present[..., None, None], joints, np.nan)
    video = root / info['video_path'].format(
        video_key=video_key, chunk_index=row[f'videos/{video_key}/chunk_index'],
        file_index=row[f'videos/{video_key}/file_index'])
    first = round(row[f'videos/{video_key}/from_timestamp'] * info['fps'])
    height, width = info['features'][video_key]['shape'][:2]
    return CorpusSequence(
        sequence_id=f'{root.name}.episode{row["episode_index"]:06d}', source=SOURCE,
        licence=LICENCE, image_size=(int(width), int(height)),
        timestamp_ns=np.asarray(table[feat.SOURCE_STAMP], np.int64).reshape(-1), K=K,
        T_world_cam=T_world_cam, hand_present=present, joints_cam=joints,
        joint_valid=np.repeat(present[..., None], NUM_JOINTS, axis=2), mano_cam=None,
        read_rgb=VideoFrames(video, first))


def read_lerobot_dataset(root: Path) -> Iterator[CorpusSequence]:
    """Yield the episodes of one dataset written by ``bag_to_dataset``."""
    root = Path(root)
    try:
        info = json.loads((root / INFO_FILE).read_text(encoding='utf-8'))
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(f'{root}: not a LeRobot dataset ({exc}); give a bag_to_dataset '
                         'output directory') from exc
    videos = [key for key, spec in info['features'].items() if spec.get('dtype') == 'video']
    missing = [k for k in (feat.CAMERA_POSE, feat.KEYPOINTS_WORLD) if k not in info['features']]
    if len(videos) != 1 or missing:
        raise InputError(f'{root}: expected one video and the features {missing} of '
                         'bag_to_dataset; is this another LeRobot dataset?')
    for path in sorted(root.glob(EPISODES_GLOB)):
        for row in pq.read_table(path).to_pylist():
            yield _episode(root, info, row, videos[0])


def iter_lerobot(roots: list[Path]) -> Iterator[CorpusSequence]:
    """Yield the episodes of every dataset (a folder with ``meta/info.json``) under roots."""
    for root in map(Path, roots):
        for info in sorted(root.glob(f'**/{INFO_FILE}')):
            yield from read_lerobot_dataset(info.parent.parent)
