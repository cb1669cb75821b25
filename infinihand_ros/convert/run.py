"""A conversion run: every input, episode by episode, into one dataset, past any bad input.

Each input is read as a stream (bag or video), its frames are checked (``source_frames``),
split into episodes (one per input, or per time window) and converted through one engine that
is reset between episodes. An input that fails is reported with its path and the reason and the
run goes on; an episode already in the dataset (same source) is skipped.
"""

from collections import Counter
from collections.abc import Generator
from collections.abc import Iterator
import contextlib
from dataclasses import dataclass
from dataclasses import replace
import itertools
import logging
from pathlib import Path
from typing import Any, Protocol

from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.convert.bag_frames import read_bag_frames
from infinihand_ros.convert.config import ConvertConfig
from infinihand_ros.convert.episode import ConversionError
from infinihand_ros.convert.episode import convert_episode
from infinihand_ros.convert.episode import EpisodeData
from infinihand_ros.convert.frame_log import FrameLog
from infinihand_ros.convert.image_fit import FrameFitter
from infinihand_ros.convert.image_fit import needs_fit
from infinihand_ros.convert.image_fit import parse_video_size
from infinihand_ros.convert.image_frames import read_image_frames
from infinihand_ros.convert.inputs import IMAGES
from infinihand_ros.convert.inputs import InputSource
from infinihand_ros.convert.inputs import VIDEO
from infinihand_ros.convert.provenance import provenance_of
from infinihand_ros.convert.report import EpisodeReport
from infinihand_ros.convert.report import FAILED
from infinihand_ros.convert.report import SKIPPED
from infinihand_ros.convert.source_frames import checked_frames
from infinihand_ros.convert.source_frames import SourceFrame
from infinihand_ros.convert.source_frames import split_windows
from infinihand_ros.convert.video_frames import read_video_frames
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.settings import build_engine_config
from infinihand_ros.engine.streaming_engine import StreamingEngine
from tqdm import tqdm

logger = logging.getLogger(__name__)

#: Sidecar files holding an input's task: ``<input>.task.txt`` beside it, or inside a bag folder.
TASK_SUFFIX = '.task.txt'
TASK_FILE = 'task.txt'


@dataclass(frozen=True)
class RunOptions:
    """What a run converts besides the settings file.

    Attributes:
        output: the dataset directory.
        image_topic: the bags' image topic, or None to auto-detect it per bag.
        intrinsics: intrinsics of video inputs and image sequences, or None (predicted).
        input_fps: the rate image sequences were taken at (their files carry no times).
        progress: show progress bars.

    """

    output: Path
    image_topic: str | None = None
    intrinsics: Intrinsics | None = None
    progress: bool = True
    input_fps: float | None = None


class EpisodeSink(Protocol):
    """Where converted episodes go: the dataset (``DatasetWriter``) or a worker's shard."""

    def finished_sources(self) -> set[str]:
        """Return the sources whose episodes are already done."""

    def staging(self) -> contextlib.AbstractContextManager[Path]:
        """Return a context giving a fresh working directory for one episode."""

    def add(self, episode: EpisodeData, task: str) -> int:
        """Keep a converted episode; return its index."""


def engine_config_for(config: ConvertConfig) -> EngineConfig:
    """Return the engine settings of ``config.engine`` (profile, file, overrides)."""
    choice = config.engine
    return build_engine_config(choice.profile, choice.overrides, choice.config or None)


def task_for(source: InputSource, config: ConvertConfig) -> str:
    """Return the input's task: the configured one, else its sidecar file, else the default."""
    if config.task:
        return config.task
    candidates = [source.path.with_name(source.path.name + TASK_SUFFIX)]
    if source.path.is_dir():
        candidates.append(source.path / TASK_FILE)
    for candidate in candidates:
        if candidate.is_file():
            text = candidate.read_text(encoding='utf-8').strip()
            if text:
                return text
    return config.default_task


class ConversionRun:
    """Converts inputs into the dataset of ``options.output``; collects the reports."""

    def __init__(self, config: ConvertConfig, options: RunOptions, writer: EpisodeSink,
                 reports: list[EpisodeReport] | None = None) -> None:
        """Prepare a run (the engine is built when the first episode needs it).

        Args:
            config: the converter settings.
            options: what to convert besides the settings.
            writer: receives each converted episode.
            reports: list the reports are appended to (a new one when None).

        """
        self.config = config
        self.options = options
        self.writer = writer
        self.reports: list[EpisodeReport] = [] if reports is None else reports
        self._engine: StreamingEngine | None = None
        self._typestore = build_typestore() if config.estimates_bag else None
        self._marks: tuple[int, Counter, Counter] = (0, Counter(), Counter())
        self._provenance: dict[str, Any] = {}

    def close(self) -> None:
        """Stop the engine's workers."""
        if self._engine is not None:
            self._engine.close()

    def _engine_instance(self) -> StreamingEngine:
        if self._engine is None:
            engine_config = engine_config_for(self.config)
            self._provenance = provenance_of(engine_config).to_dict()
            self._engine = StreamingEngine(engine_config)
        return self._engine

    def convert(self, source: InputSource) -> None:
        """Convert one input into one or more episodes; failures become reports."""
        log = FrameLog()
        self._marks = (0, Counter(), Counter())
        windowed = self.config.episode_max_s is not None
        seen = False
        name = str(source.path)
        layout = self.config.dataset
        fitter = FrameFitter(parse_video_size(layout.video_size), layout.resize)
        try:
            frames = (fitter.fit(frame) for frame in checked_frames(
                read_source_frames(source, self.options, log), log))
            groups = itertools.groupby(split_windows(frames, self.config.episode_max_s),
                                       key=lambda pair: pair[0])
            for window, pairs in groups:
                seen = True
                name = f'{source.path}#{window}' if windowed else str(source.path)
                self._episode(source, name, (frame for _, frame in pairs), log, fitter)
            if not seen:
                raise ConversionError(_no_frame_message(log))
        except (InfiniHandError, OSError) as exc:
            self.reports.append(EpisodeReport(name, status=FAILED, error=str(exc)))
            logger.error('%s: %s', name, exc)

    def _episode(self, source: InputSource, name: str, frames: Iterator[SourceFrame],
                 log: FrameLog, fitter: FrameFitter) -> None:
        """Convert (or skip) one episode of ``source``."""
        if name in self.writer.finished_sources():
            for _ in frames:
                pass
            self.reports.append(EpisodeReport(name, status=SKIPPED))
            return
        # Counts since the previous episode of this input ended (a window boundary frame read
        # ahead by the grouping counts towards the earlier episode).
        read, skipped, warned = self._marks
        report = EpisodeReport(name)
        with self.writer.staging() as work, tqdm(
                desc=source.path.name, unit='frame', leave=False,
                disable=not self.options.progress) as bar:
            try:
                episode = convert_episode(frames, self._engine_instance(), self.config, work,
                                          report, self._typestore, bar.update)
            finally:
                report.frames_in = log.read - read
                report.skipped = dict(log.skipped - skipped)
                report.warnings = dict(log.warnings - warned)
                self._marks = (log.read, Counter(log.skipped), Counter(log.warnings))
            episode = replace(episode, image=dict(fitter.record or {}),
                              provenance=self._provenance)
            self.writer.add(episode, task_for(source, self.config))
        self.reports.append(report)


def read_source_frames(source: InputSource, options: RunOptions,
                       log: FrameLog) -> Generator[SourceFrame, None, None]:
    """Return the stream of ``source``'s frames as read (before any check)."""
    if source.kind == VIDEO:
        return read_video_frames(source.path, options.intrinsics, log)
    if source.kind == IMAGES:
        return read_image_frames(source.path, options.input_fps, options.intrinsics, log)
    return read_bag_frames(source.path, options.image_topic, log)


def resolve_video_size(config: ConvertConfig, dataset_size: tuple[int, int] | None,
                       sources: list[InputSource], options: RunOptions) -> ConvertConfig:
    """Return ``config`` with the dataset's video size set, so every worker fits to it.

    The size is ``convert.dataset.video_size`` when set, else the existing dataset's, else the
    first frame of the first input that has one (inputs that cannot be read are left to fail
    in the run); unchanged when no input has a frame.

    Raises:
        ConversionError: when the configured size differs from the existing dataset's.

    """
    configured = parse_video_size(config.dataset.video_size)
    if configured is not None:
        if dataset_size is not None and needs_fit(configured, dataset_size):
            raise ConversionError(
                f"--video-size {configured[0]}x{configured[1]}: the dataset's videos are "
                f'{dataset_size[0]}x{dataset_size[1]}; leave it out to extend the dataset')
        return config
    size = dataset_size
    for source in sources if size is None else ():
        log = FrameLog()
        try:
            with contextlib.closing(read_source_frames(source, options, log)) as frames:
                first = next(checked_frames(frames, log), None)
        except (InfiniHandError, OSError):
            continue
        if first is not None:
            size = (first.rgb.shape[1], first.rgb.shape[0])
            break
    if size is None:
        return config
    return replace(config, dataset=replace(config.dataset, video_size=f'{size[0]}x{size[1]}'))


def _no_frame_message(log: FrameLog) -> str:
    """Say why an input gave no frame: what was read and every reason frames were dropped."""
    reasons = '; '.join(f'{count} x {reason}' for reason, count in log.skipped.items())
    return (f'no usable frame ({log.read} image messages read'
            + (f', skipped: {reasons})' if reasons else ')'))
