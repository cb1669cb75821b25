"""A LeRobot v3.0 dataset that grows one episode at a time and is valid after every step.

Adding an episode writes its data file and moves its video (and bag of estimates) into place,
then replaces the whole ``meta/`` directory at once (``core.atomic_io.atomic_directory``): the
metadata is the record of what the dataset holds. A run that stops anywhere (Ctrl-C, a crash, a
full disk) leaves the previous metadata, and files it does not list are removed when the next
run opens the dataset; episodes converted by an earlier run are skipped by their source. The
dataset card (``README.md``, ``dataset_card``) is written atomically after ``meta/`` and again
when a run opens a dataset whose card is not its metadata's.
"""

from collections.abc import Iterator
import contextlib
import io
import json
import logging
import os
from pathlib import Path
import shutil
import tempfile
from typing import Any, Final

from infinihand_ros.convert import lerobot_layout as layout
from infinihand_ros.convert.config import ConvertConfig
from infinihand_ros.convert.dataset_card import CARD_FILE
from infinihand_ros.convert.dataset_card import dataset_card
from infinihand_ros.convert.episode import ConversionError
from infinihand_ros.convert.episode import EpisodeData
from infinihand_ros.convert.lerobot_features import EPISODE_INDEX
from infinihand_ros.convert.lerobot_features import INDEX
from infinihand_ros.convert.lerobot_features import TASK_INDEX
from infinihand_ros.convert.stats import merge_stats
from infinihand_ros.convert.stats import vector_stats
from infinihand_ros.core.atomic_io import atomic_directory
from infinihand_ros.core.atomic_io import atomic_write_bytes
from infinihand_ros.core.config import config_to_dict
from infinihand_ros.core.errors import InputError
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

logger = logging.getLogger(__name__)

#: Prefix of the per-episode working directories inside the dataset root.
STAGING_PREFIX: Final = '.episode-'


class DatasetWriter:
    """The dataset at ``root``: opened (or created) by the constructor, grown by ``add``."""

    def __init__(self, root: Path, config: ConvertConfig) -> None:
        """Open the dataset at ``root`` and remove what an interrupted run left behind.

        Raises:
            InputError: when ``root`` holds something else, or a dataset whose fps or
                features differ from ``config``'s.

        """
        self.root = Path(root)
        self.config = config
        self._rows: list[dict[str, Any]] = []
        self._tasks: list[str] = []
        self._records: list[dict[str, Any]] = []
        self._info: dict[str, Any] | None = None
        if (self.root / layout.INFO_PATH).is_file():
            self._load()
        elif self.root.exists() and any(not p.name.startswith('.') for p in self.root.iterdir()):
            raise InputError(f'--output {self.root} exists and is not a LeRobot dataset written '
                             'by bag_to_dataset; choose a new or empty directory')
        self.root.mkdir(parents=True, exist_ok=True)
        self._remove_leftovers()

    @property
    def num_episodes(self) -> int:
        """Return the number of episodes in the dataset."""
        return len(self._rows)

    @property
    def video_size(self) -> tuple[int, int] | None:
        """Return (width, height) of the dataset's videos, or None before the first episode."""
        if self._info is None:
            return None
        height, width = self._info['features'][self.config.dataset.video_key]['shape'][:2]
        return width, height

    def finished_sources(self) -> set[str]:
        """Return the sources of the episodes already in the dataset."""
        return {record['source'] for record in self._records}

    @contextlib.contextmanager
    def staging(self) -> Iterator[Path]:
        """Yield a fresh working directory for one episode (removed afterwards)."""
        work = Path(tempfile.mkdtemp(prefix=STAGING_PREFIX, dir=self.root))
        try:
            yield work
        finally:
            shutil.rmtree(work, ignore_errors=True)

    def add(self, episode: EpisodeData, task: str) -> int:
        """Add a converted episode; return its episode index.

        Raises:
            ConversionError: when its video size differs from the dataset's.
            OSError: when a file cannot be written (the dataset keeps its previous episodes).

        """
        index, config = self.num_episodes, self.config
        features = layout.feature_infos(config.dataset.video_key, episode.video, config.fps)
        if self._info is not None and features != self._info['features']:
            raise ConversionError(_features_difference(self._info['features'], features))
        if task not in self._tasks:
            self._tasks.append(task)
        from_index = sum(row['length'] for row in self._rows)
        columns = dict(episode.columns)
        columns[EPISODE_INDEX] = np.full((episode.length, 1), index, dtype=np.int64)
        columns[INDEX] = from_index + np.arange(episode.length, dtype=np.int64)[:, None]
        columns[TASK_INDEX] = np.full((episode.length, 1), self._tasks.index(task), np.int64)
        stats = {key: vector_stats(values) for key, values in columns.items()}
        stats[config.dataset.video_key] = episode.image_stats
        row = layout.episode_row(index, task, episode.length, from_index, config.fps,
                                 config.dataset.chunks_size, config.dataset.video_key, stats)
        placed = self._place_files(index, columns, episode)
        episode.report.episode_index = index
        record = {'episode_index': index, 'source': episode.report.source, 'task': task,
                  'image': episode.image, 'lens': episode.lens,
                  'provenance': episode.provenance,
                  'report': episode.report.to_dict()}
        try:
            self._write_meta(self._rows + [row], self._records + [record], features)
        except BaseException:
            for path in placed:
                _remove(path)
            episode.report.episode_index = -1
            raise
        self._rows.append(row)
        self._records.append(record)
        self._info = json.loads((self.root / layout.INFO_PATH).read_text(encoding='utf-8'))
        try:
            self._write_card(self._info, self._records)
        except OSError as exc:  # the episode is in; the card follows on the next open
            logger.error('%s: dataset card not written (%s); the next run writes it',
                         self.root / CARD_FILE, exc)
        return index

    def _paths(self, index: int) -> dict[str, Path]:
        chunk, file = layout.chunk_and_file(index, self.config.dataset.chunks_size)
        return {
            'data': self.root / layout.DATA_PATH.format(chunk_index=chunk, file_index=file),
            'video': self.root / layout.VIDEO_PATH.format(
                video_key=self.config.dataset.video_key, chunk_index=chunk, file_index=file),
            'estimates': self.root / layout.ESTIMATES_PATH.format(episode_index=index)}

    def _place_files(self, index: int, columns: dict[str, np.ndarray],
                     episode: EpisodeData) -> list[Path]:
        """Write the data file and move the video and estimates in; return what was placed."""
        paths, placed = self._paths(index), []
        try:
            buffer = io.BytesIO()
            pq.write_table(layout.data_table(columns), buffer)
            atomic_write_bytes(paths['data'], buffer.getvalue())
            placed.append(paths['data'])
            paths['video'].parent.mkdir(parents=True, exist_ok=True)
            os.replace(episode.video_path, paths['video'])
            placed.append(paths['video'])
            if episode.estimates_bag is not None:
                _remove(paths['estimates'])
                paths['estimates'].parent.mkdir(parents=True, exist_ok=True)
                os.replace(episode.estimates_bag, paths['estimates'])
                placed.append(paths['estimates'])
        except BaseException:
            for path in placed:
                _remove(path)
            raise
        return placed

    def _write_meta(self, rows: list[dict[str, Any]], records: list[dict[str, Any]],
                    features: dict[str, Any]) -> None:
        """Replace ``meta/`` with the metadata of ``rows`` (all or nothing)."""
        config = self.config
        info = layout.info_json(features, config.dataset.robot_type, config.fps,
                                config.dataset.chunks_size, len(rows),
                                sum(row['length'] for row in rows), len(self._tasks))
        per_feature: dict[str, list] = {}
        for row in rows:
            for key, stats in layout.stats_from_row(row).items():
                per_feature.setdefault(key, []).append(stats)
        merged = {key: layout.stats_to_lists(merge_stats(parts))
                  for key, parts in per_feature.items()}
        provenance = list({json.dumps(r['provenance'], sort_keys=True): r['provenance']
                           for r in records if r.get('provenance')}.values())
        conversion = {'episodes': records, 'provenance': provenance,
                      'config': config_to_dict(config)}
        with atomic_directory(self.root / 'meta', overwrite=True) as work:
            meta_root = work.parent
            files = {
                layout.INFO_PATH: json.dumps(info, indent=4).encode(),
                layout.STATS_PATH: json.dumps(merged, indent=4).encode(),
                layout.CONVERSION_PATH: json.dumps(conversion, indent=2).encode(),
                layout.TASKS_PATH: _parquet_bytes(layout.tasks_table(self._tasks)),
                layout.EPISODES_PATH: _parquet_bytes(pa.Table.from_pylist(rows))}
            for relative, data in files.items():
                path = meta_root / relative
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(data)

    def _write_card(self, info: dict[str, Any], records: list[dict[str, Any]]) -> None:
        """Write the dataset card (atomically) when it differs from the metadata's."""
        card = dataset_card(info, records, self._tasks).encode()
        path = self.root / CARD_FILE
        if not path.is_file() or path.read_bytes() != card:
            atomic_write_bytes(path, card)

    def _load(self) -> None:
        """Read the dataset's metadata and check it matches the config."""
        info = json.loads((self.root / layout.INFO_PATH).read_text(encoding='utf-8'))
        if info.get('codebase_version') != layout.CODEBASE_VERSION or info.get(
                'fps') != self.config.fps:
            raise InputError(f'--output {self.root} is a LeRobot {info.get("codebase_version")} '
                             f'dataset at {info.get("fps")} fps; extend it with --fps '
                             f'{info.get("fps")} or write to another --output')
        self._info = info
        self._rows = pq.read_table(self.root / layout.EPISODES_PATH).to_pylist()
        self._tasks = pq.read_table(self.root / layout.TASKS_PATH).column('task').to_pylist()
        conversion = json.loads((self.root / layout.CONVERSION_PATH).read_text(encoding='utf-8'))
        self._records = conversion['episodes']
        self._write_card(info, self._records)  # a run stopped between meta/ and the card

    def _remove_leftovers(self) -> None:
        """Remove staging directories and files no episode row lists (an interrupted add)."""
        for path in self.root.iterdir():
            if path.name.startswith((STAGING_PREFIX, '.meta.', f'.{CARD_FILE}.')):
                _remove(path)
        listed = {path for index in range(self.num_episodes)
                  for path in self._paths(index).values()}
        patterns = ('data/*/*', f'videos/{self.config.dataset.video_key}/*/*', 'estimates/*')
        for pattern in patterns:
            for path in self.root.glob(pattern):
                if path not in listed:
                    _remove(path)


def _features_difference(dataset: dict[str, Any], episode: dict[str, Any]) -> str:
    """Say how an episode's features differ from the dataset's."""
    keys = sorted(set(dataset) ^ set(episode))
    if keys:
        return (f'the dataset was written with other features (not both have {keys}); '
                'convert into another --output')
    changed = sorted(key for key in dataset if dataset[key] != episode[key])
    return (f"features {changed} differ from the dataset's ({[dataset[k] for k in changed]} "
            f'vs {[episode[k] for k in changed]}); convert into another --output')


def _parquet_bytes(table: pa.Table) -> bytes:
    buffer = io.BytesIO()
    pq.write_table(table, buffer)
    return buffer.getvalue()


def _remove(path: Path) -> None:
    """Delete a file or directory tree if it exists."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif os.path.lexists(path):
        path.unlink()
