"""The adapter of our bag converter's LeRobot v3.0 output, on a tiny dataset in that layout."""

import io
import json
from pathlib import Path

from dataset_layouts import frames_rgb
from dataset_layouts import HEIGHT
from dataset_layouts import K
from dataset_layouts import random_poses
from dataset_layouts import WIDTH
from infinihand_ros.convert import lerobot_features as feat
from infinihand_ros.convert import lerobot_layout as layout
from infinihand_ros.convert.config import VideoSettings
from infinihand_ros.convert.video_writer import EpisodeVideoWriter
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.corpus.adapters.lerobot_bags import iter_lerobot
from infinihand_ros.synth.known_tracks import known_track
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

FRAMES, FPS, KEY = 4, 10, 'observation.images.ego'


def _write(path: Path, table: pa.Table) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    pq.write_table(table, buffer)
    path.write_bytes(buffer.getvalue())


def _dataset(root: Path, joints: np.ndarray, poses: np.ndarray) -> Path:
    """One episode whose right hand is ``joints`` (camera frame) and left hand is invalid."""
    video = root / layout.VIDEO_PATH.format(video_key=KEY, chunk_index=0, file_index=0)
    video.parent.mkdir(parents=True)
    with EpisodeVideoWriter(video, FPS, VideoSettings()) as writer:
        for rgb in frames_rgb(FRAMES):
            writer.write(rgb)
        video_info = writer.close()
    world = np.einsum('tij,tnj->tni', poses[:, :3, :3], joints) + poses[:, None, :3, 3]
    columns = {spec.key: np.zeros((FRAMES, spec.shape[0])) for spec in feat.FRAME_FEATURES}
    columns[feat.CAMERA_POSE] = poses.reshape(FRAMES, 16)
    columns[feat.INTRINSICS] = np.tile([K[0, 0], K[1, 1], K[0, 2], K[1, 2]], (FRAMES, 1))
    columns[feat.HAND_VALID] = np.tile([0.0, 1.0], (FRAMES, 1))
    columns[feat.KEYPOINTS_WORLD] = np.concatenate(
        [np.zeros((FRAMES, 63)), world.reshape(FRAMES, 63)], axis=1)
    columns[feat.SOURCE_STAMP] = 1_000 + 100 * np.arange(FRAMES)[:, None]
    for key in feat.DEFAULT_FEATURES:
        columns[key] = np.zeros((FRAMES, 1))
    columns[feat.TIMESTAMP] = np.arange(FRAMES)[:, None] / FPS
    _write(root / layout.DATA_PATH.format(chunk_index=0, file_index=0),
           layout.data_table(columns))
    features = layout.feature_infos(KEY, video_info, FPS)
    (root / 'meta').mkdir()
    (root / layout.INFO_PATH).write_text(json.dumps(layout.info_json(
        features, 'hand', FPS, 1000, 1, FRAMES, 1)))
    _write(root / layout.EPISODES_PATH, pa.Table.from_pylist([layout.episode_row(
        0, 'task', FRAMES, 0, FPS, 1000, KEY, {})]))
    return root


def test_converter_output_hand_lands_in_its_camera(tmp_path: Path) -> None:
    """World keypoints and camera poses give back the camera-frame right hand; left absent."""
    joints = known_track(np.random.default_rng(8), RIGHT, FRAMES).joints
    poses = random_poses(np.random.default_rng(9), FRAMES)
    sequence = next(iter_lerobot([_dataset(tmp_path / 'ds', joints, poses)]))
    assert sequence.source == 'infinihand-bags' and sequence.sequence_id == 'ds.episode000000'
    np.testing.assert_allclose(sequence.joints_cam[:, RIGHT], joints, atol=1e-5)
    assert sequence.hand_present[:, RIGHT].all() and not sequence.hand_present[:, LEFT].any()
    np.testing.assert_allclose(sequence.K[0], K, atol=1e-5)
    assert sequence.timestamp_ns.tolist() == [1000, 1100, 1200, 1300]
    assert sequence.image_size == (WIDTH, HEIGHT)
    assert sequence.read_rgb(3).shape == (HEIGHT, WIDTH, 3)


def test_another_dataset_is_rejected(tmp_path: Path) -> None:
    """A folder with an info.json lacking our features is an InputError saying so."""
    (tmp_path / 'meta').mkdir()
    (tmp_path / 'meta' / 'info.json').write_text(json.dumps({'features': {}}))
    with pytest.raises(ValueError, match='bag_to_dataset'):
        next(iter_lerobot([tmp_path]))
