"""The LeRobot v3.0 layout: paths, ``info.json``, episode rows, data and task tables.

Read with LeRobot's own reader in mind (``lerobot.datasets.utils`` at v0.4): a feature of shape
(1,) is a scalar column, a longer 1-D one a fixed-size list; ``meta/tasks.parquet`` has the
task string as its pandas index and a ``task_index`` column; each episode row points at its
data file, its video file and the time span of its video. This converter writes one data file
and one video file per episode (``file_index`` = episode index within its chunk), which the
layout allows, so each episode is added without rewriting any earlier file.
"""

import json
from typing import Any, Final

from infinihand_ros.convert.lerobot_features import DEFAULT_FEATURES
from infinihand_ros.convert.lerobot_features import FeatureSpec
from infinihand_ros.convert.lerobot_features import FRAME_FEATURES
from infinihand_ros.convert.stats import Stats
from infinihand_ros.convert.video_writer import VideoInfo
import numpy as np
import pyarrow as pa

CODEBASE_VERSION: Final = 'v3.0'
INFO_PATH: Final = 'meta/info.json'
STATS_PATH: Final = 'meta/stats.json'
TASKS_PATH: Final = 'meta/tasks.parquet'
EPISODES_PATH: Final = 'meta/episodes/chunk-000/file-000.parquet'
#: Our own record of each episode's source and report (LeRobot ignores it).
CONVERSION_PATH: Final = 'meta/infinihand_conversion.json'
DATA_PATH: Final = 'data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet'
VIDEO_PATH: Final = 'videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4'
ESTIMATES_PATH: Final = 'estimates/episode_{episode_index:06d}'
#: LeRobot's file-size targets, written for its tools (each of our files holds one episode).
DATA_FILES_SIZE_IN_MB: Final = 100
VIDEO_FILES_SIZE_IN_MB: Final = 200
#: FFmpeg encoder -> codec name LeRobot writes in ``video.codec``.
CODEC_NAMES: Final = {'libx264': 'h264', 'libsvtav1': 'av1'}
ARROW_TYPES: Final = {'float32': pa.float32(), 'int64': pa.int64(), 'bool': pa.bool_()}


def chunk_and_file(episode_index: int, chunks_size: int) -> tuple[int, int]:
    """Return (chunk_index, file_index) of an episode's data and video files."""
    return divmod(episode_index, chunks_size)


def feature_infos(video_key: str, video: VideoInfo, fps: int) -> dict[str, dict[str, Any]]:
    """Return the ``features`` of ``info.json``."""
    features: dict[str, dict[str, Any]] = {
        video_key: {
            'dtype': 'video', 'shape': [video.height, video.width, 3],
            'names': ['height', 'width', 'channels'],
            'info': {'video.height': video.height, 'video.width': video.width,
                     'video.codec': CODEC_NAMES[video.codec], 'video.pix_fmt': video.pix_fmt,
                     'video.is_depth_map': False, 'video.fps': fps, 'video.channels': 3,
                     'has_audio': False}}}
    for spec in FRAME_FEATURES:
        features[spec.key] = {'dtype': spec.dtype, 'shape': list(spec.shape),
                              'names': list(spec.names)}
    for key, dtype in DEFAULT_FEATURES.items():
        features[key] = {'dtype': dtype, 'shape': [1], 'names': None}
    return features


def info_json(features: dict[str, Any], robot_type: str, fps: int, chunks_size: int,
              total_episodes: int, total_frames: int, total_tasks: int) -> dict[str, Any]:
    """Return ``meta/info.json``."""
    return {
        'codebase_version': CODEBASE_VERSION, 'robot_type': robot_type,
        'total_episodes': total_episodes, 'total_frames': total_frames,
        'total_tasks': total_tasks, 'chunks_size': chunks_size,
        'data_files_size_in_mb': DATA_FILES_SIZE_IN_MB,
        'video_files_size_in_mb': VIDEO_FILES_SIZE_IN_MB, 'fps': fps,
        'splits': {'train': f'0:{total_episodes}'}, 'data_path': DATA_PATH,
        'video_path': VIDEO_PATH, 'features': features}


def _column(spec: FeatureSpec, values: np.ndarray) -> pa.Array:
    """Return a scalar column for shape (1,), else a fixed-size list column."""
    arrow_type = ARROW_TYPES[spec.dtype]
    if spec.shape == (1,):
        return pa.array(values.reshape(-1).astype(spec.dtype), type=arrow_type)
    flat = pa.array(values.reshape(-1).astype(spec.dtype), type=arrow_type)
    return pa.FixedSizeListArray.from_arrays(flat, spec.shape[0])


def data_table(columns: dict[str, np.ndarray]) -> pa.Table:
    """Return an episode's data table: the features, then LeRobot's bookkeeping columns."""
    specs = list(FRAME_FEATURES) + [FeatureSpec(key, dtype, (key,))
                                    for key, dtype in DEFAULT_FEATURES.items()]
    return pa.table({spec.key: _column(spec, columns[spec.key]) for spec in specs})


def tasks_table(tasks: list[str]) -> pa.Table:
    """Return ``meta/tasks.parquet``: pandas reads ``task`` back as the index."""
    table = pa.table({'task_index': pa.array(range(len(tasks)), type=pa.int64()),
                      'task': pa.array(tasks, type=pa.string())})
    pandas_metadata = {
        'index_columns': ['task'],
        'column_indexes': [{'name': None, 'field_name': None, 'pandas_type': 'unicode',
                            'numpy_type': 'object', 'metadata': {'encoding': 'UTF-8'}}],
        'columns': [
            {'name': 'task_index', 'field_name': 'task_index', 'pandas_type': 'int64',
             'numpy_type': 'int64', 'metadata': None},
            {'name': 'task', 'field_name': 'task', 'pandas_type': 'unicode',
             'numpy_type': 'object', 'metadata': None}],
        'creator': {'library': 'pyarrow', 'version': pa.__version__},
        'pandas_version': '2.2.3'}
    return table.replace_schema_metadata({'pandas': json.dumps(pandas_metadata)})


def stats_to_lists(stats: Stats) -> dict[str, Any]:
    """Return statistics as JSON/parquet-ready nested lists."""
    return {name: np.asarray(value).tolist() for name, value in stats.items()}


def episode_row(episode_index: int, task: str, length: int, from_index: int, fps: int,
                chunks_size: int, video_key: str,
                stats: dict[str, Stats]) -> dict[str, Any]:
    """Return the ``meta/episodes`` row of one episode (stats flattened as ``stats/k/s``)."""
    chunk, file = chunk_and_file(episode_index, chunks_size)
    row: dict[str, Any] = {
        'episode_index': episode_index, 'tasks': [task], 'length': length,
        'data/chunk_index': chunk, 'data/file_index': file,
        'dataset_from_index': from_index, 'dataset_to_index': from_index + length,
        f'videos/{video_key}/chunk_index': chunk, f'videos/{video_key}/file_index': file,
        f'videos/{video_key}/from_timestamp': 0.0,
        f'videos/{video_key}/to_timestamp': length / fps,
        'meta/episodes/chunk_index': 0, 'meta/episodes/file_index': 0}
    for key, feature_stats in stats.items():
        for name, value in stats_to_lists(feature_stats).items():
            row[f'stats/{key}/{name}'] = value
    return row


def stats_from_row(row: dict[str, Any]) -> dict[str, Stats]:
    """Return the per-feature statistics stored in an episode row."""
    stats: dict[str, Stats] = {}
    for column, value in row.items():
        if column.startswith('stats/'):
            key, name = column[len('stats/'):].rsplit('/', 1)
            stats.setdefault(key, {})[name] = np.asarray(value)
    return stats
