"""Episode shards: one input converted by a worker, merged into the dataset by the driver.

A worker converts a whole input (all its time windows: an episode is never split) exactly as
the local run does, but keeps the finished episodes in its shard directory instead of adding
them to the dataset. The driver then adds them with ``merge_shard`` in input order, so episode
numbering, statistics and ``meta/`` are written by the one ``DatasetWriter`` (atomically per
episode, as in local mode). Plain Python: ``ray_run`` puts ``ShardConverter`` in Ray actors.
"""

from collections.abc import Iterator
import contextlib
from dataclasses import dataclass
import logging
from pathlib import Path
import shutil
import tempfile

from infinihand_ros.convert.config import ConvertConfig
from infinihand_ros.convert.dataset_writer import DatasetWriter
from infinihand_ros.convert.episode import EpisodeData
from infinihand_ros.convert.inputs import InputSource
from infinihand_ros.convert.report import CONVERTED
from infinihand_ros.convert.report import EpisodeReport
from infinihand_ros.convert.report import FAILED
from infinihand_ros.convert.run import ConversionRun
from infinihand_ros.convert.run import RunOptions
from infinihand_ros.core.errors import InfiniHandError

logger = logging.getLogger(__name__)


@dataclass
class ShardResult:
    """What a worker made of one input.

    Attributes:
        episodes: (episode, task) of each converted episode, in order; its files lie in the
            shard directory.
        reports: every report of the input (converted, skipped or failed), in order.

    """

    episodes: list[tuple[EpisodeData, str]]
    reports: list[EpisodeReport]


class ShardSink:
    """Keeps converted episodes in a shard directory (an ``EpisodeSink`` of ``ConversionRun``)."""

    def __init__(self) -> None:
        """Start without a shard (``begin`` sets one)."""
        self._root: Path | None = None
        self._finished: set[str] = set()
        self._episodes: list[tuple[EpisodeData, str]] = []

    def begin(self, root: Path, finished: set[str]) -> None:
        """Start a shard in directory ``root`` (created); the ``finished`` sources are skipped."""
        self._root, self._finished, self._episodes = Path(root), set(finished), []
        self._root.mkdir(parents=True, exist_ok=True)

    def take(self) -> list[tuple[EpisodeData, str]]:
        """Return the episodes of the shard (and forget them)."""
        episodes, self._episodes = self._episodes, []
        return episodes

    def finished_sources(self) -> set[str]:
        """Return the sources already in the dataset."""
        return self._finished

    @contextlib.contextmanager
    def staging(self) -> Iterator[Path]:
        """Yield a fresh directory in the shard; it is kept once its episode was added."""
        work = Path(tempfile.mkdtemp(prefix='episode-', dir=self._root))
        count = len(self._episodes)
        try:
            yield work
        finally:
            if len(self._episodes) == count:
                shutil.rmtree(work, ignore_errors=True)

    def add(self, episode: EpisodeData, task: str) -> int:
        """Keep the episode for the driver; return its place in the shard."""
        self._episodes.append((episode, task))
        return len(self._episodes) - 1


class ShardConverter:
    """One engine converting inputs into shards, one input per call (a Ray actor's body)."""

    def __init__(self, config: ConvertConfig, options: RunOptions) -> None:
        """Prepare the run (the engine is built with the first episode and kept)."""
        self._sink = ShardSink()
        self._run = ConversionRun(config, options, self._sink)

    def convert(self, source: InputSource, shard: Path, finished: set[str]) -> ShardResult:
        """Convert ``source`` into the directory ``shard``, skipping ``finished`` sources."""
        self._sink.begin(shard, finished)
        self._run.convert(source)
        reports = list(self._run.reports)
        self._run.reports.clear()
        return ShardResult(self._sink.take(), reports)

    def close(self) -> None:
        """Stop the engine's workers."""
        self._run.close()


def merge_shard(writer: DatasetWriter, shard: ShardResult,
                reports: list[EpisodeReport]) -> None:
    """Add a shard's episodes to the dataset and append the input's reports to ``reports``.

    An episode the dataset refuses (another video size, a full disk) is reported as failed
    with the reason, and the input's later episodes are dropped, as the local run stops an
    input at its first failure.
    """
    episodes = iter(shard.episodes)
    for report in shard.reports:
        if report.status != CONVERTED:
            reports.append(report)
            continue
        episode, task = next(episodes)
        try:
            writer.add(episode, task)
        except (InfiniHandError, OSError) as exc:
            reports.append(EpisodeReport(report.source, status=FAILED, error=str(exc)))
            logger.error('%s: %s', report.source, exc)
            return
        reports.append(episode.report)
