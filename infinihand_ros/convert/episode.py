"""One episode through the engine: checked source frames in, dataset columns and a video out.

The frames are resampled to the dataset's fps first (``resample``); each source frame an output
frame uses is pushed to the engine once, so the engine sees the stream at (at most) the output
rate. Video frames and image statistics are written as frames arrive; the engine's results
(without depth maps) are kept until the episode ends, when they are placed on the final
trajectory (``StreamingEngine.refined``: every BA correction, the final metric scale) and turned
into feature vectors and estimates, and ``action`` (the state ``action_offset`` frames later;
the last frames repeat the final state) can be filled in. The episode's lens (``lens_record``:
the distortion model and coefficients its intrinsics carried) goes into its record; the video
keeps the source's distortion, so ``camera.intrinsics`` and the lens describe its pixels.
"""

from collections import Counter
from collections.abc import Callable
from collections.abc import Iterable
import dataclasses
from dataclasses import dataclass
from dataclasses import field
from pathlib import Path
import time
from typing import Any

from infinihand_ros.convert.config import ConvertConfig
from infinihand_ros.convert.estimates_bag import EstimatesBagWriter
from infinihand_ros.convert.hand_accounting import account_hands
from infinihand_ros.convert.lerobot_features import ACTION
from infinihand_ros.convert.lerobot_features import CAMERA_FLAG_NAMES
from infinihand_ros.convert.lerobot_features import CAMERA_FLAGS
from infinihand_ros.convert.lerobot_features import FRAME_INDEX
from infinihand_ros.convert.lerobot_features import frame_values
from infinihand_ros.convert.lerobot_features import HAND_VALID
from infinihand_ros.convert.lerobot_features import RESULT_FEATURES
from infinihand_ros.convert.lerobot_features import SOURCE_STAMP
from infinihand_ros.convert.lerobot_features import STATE
from infinihand_ros.convert.lerobot_features import TIMESTAMP
from infinihand_ros.convert.report import EpisodeReport
from infinihand_ros.convert.resample import output_time_ns
from infinihand_ros.convert.resample import resample
from infinihand_ros.convert.source_frames import SourceFrame
from infinihand_ros.convert.stats import ImageStats
from infinihand_ros.convert.stats import Stats
from infinihand_ros.convert.video_writer import EpisodeVideoWriter
from infinihand_ros.convert.video_writer import VideoInfo
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.engine.streaming_engine import StreamingEngine
import numpy as np
from rosbags.typesys.store import Typestore

VIDEO_FILE = 'video.mp4'
ESTIMATES_FILE = 'estimates'


class ConversionError(InfiniHandError):
    """An episode that cannot be converted (no usable frame, engine refusal, ...)."""


@dataclass
class EpisodeData:
    """A converted episode, not yet part of the dataset.

    Attributes:
        columns: feature key -> (N, D) values (N output frames), ``timestamp`` and
            ``frame_index`` included; episode and dataset indices are set when it is added.
        video_path: the encoded video.
        video: what the video holds.
        image_stats: the video's statistics.
        estimates_bag: the MCAP bag of the estimates, or None.
        report: the episode's report (filled in).
        image: how the source frames were fitted to the video (``image_fit.mapping_record``).
        provenance: what converted it (``provenance.Provenance.to_dict``).
        lens: the video's lens distortion (``lens_record``).

    """

    columns: dict[str, np.ndarray]
    video_path: Path
    video: VideoInfo
    image_stats: Stats
    estimates_bag: Path | None
    report: EpisodeReport
    image: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    lens: dict[str, Any] = field(default_factory=dict)

    @property
    def length(self) -> int:
        """Return the number of output frames."""
        return len(self.columns[TIMESTAMP])


class _Collector:
    """Engine results -> feature values by engine frame index, and the bag of estimates."""

    def __init__(self, fill: float, bag: EstimatesBagWriter | None) -> None:
        self.values: dict[int, dict[str, np.ndarray]] = {}
        self.reasons: dict[int, dict[str, str]] = {}
        self._fill = fill
        self._bag = bag

    def add(self, results: list[FrameResult]) -> None:
        for result in results:
            self.values[result.frame_index], self.reasons[result.frame_index] = frame_values(
                result, self._fill)
            if self._bag is not None:
                self._bag.write(result)


def convert_episode(frames: Iterable[SourceFrame], engine: StreamingEngine,
                    config: ConvertConfig, work_dir: Path, report: EpisodeReport,
                    typestore: Typestore | None = None,
                    on_frame: Callable[[], None] | None = None) -> EpisodeData:
    """Run one episode's frames through ``engine`` (reset afterwards) into ``work_dir``.

    Args:
        frames: the episode's checked frames (increasing stamps, one size).
        engine: the engine; it is reset when the episode ends, whatever happens.
        config: the converter settings.
        work_dir: existing directory for the video and the bag of estimates.
        report: this episode's report; frame counts, hands and engine figures are filled in.
        typestore: typestore of ``bag.typestore.build_typestore()``; a bag of the estimates is
            written when it is given.
        on_frame: called after each output frame (progress bars).

    Raises:
        ConversionError: when no frame is usable or the engine refuses a frame.

    """
    start = time.perf_counter()
    bag = None if typestore is None else EstimatesBagWriter(
        work_dir / ESTIMATES_FILE, typestore, config.estimates_path_length)
    collector = _Collector(config.dataset.invalid_fill, bag)
    results: list[FrameResult] = []  # live results, placed on the final trajectory at the end
    push_of_slot: list[int] = []
    source_stamps: list[int] = []
    image_stats = ImageStats()
    video_path = work_dir / VIDEO_FILE
    last_source = -1
    source_before = engine.statistics['hands']
    try:
        with EpisodeVideoWriter(video_path, config.fps, config.video) as video:
            for out in resample(((f.timestamp_ns, f) for f in frames), config.fps):
                if out.source_index != last_source:
                    results += _without_depth(_push(engine, out.item))
                    last_source = out.source_index
                    report.frames_used += 1
                push_of_slot.append(report.frames_used - 1)
                source_stamps.append(out.source_stamp_ns)
                video.write(out.item.rgb)
                image_stats.add(out.item.rgb)
                if on_frame is not None:
                    on_frame()
            if not push_of_slot:
                raise ConversionError('no usable frame')
            results += _without_depth(engine.flush())
            collector.add(engine.refined(results))
            video_info = video.close()
        statistics = engine.statistics
        report.metric_scale = float(statistics['metric_scale'])
        report.bundle_adjustment = statistics['ba']
        report.hands_found = account_hands(
            source_before, statistics['hands'],
            int(sum(values[HAND_VALID].sum() for values in collector.values.values())),
            collector.reasons.values())
    finally:
        engine.reset()
        if bag is not None:
            bag.close()
    columns = _columns(collector, push_of_slot, source_stamps, config)
    _fill_report(report, columns, collector, push_of_slot, source_stamps, config)
    report.seconds = time.perf_counter() - start
    return EpisodeData(columns, video_path, video_info, image_stats.stats(),
                       bag.path if bag is not None else None, report, lens=lens_record(results))


def lens_record(results: list[FrameResult]) -> dict[str, Any]:
    """Return the episode's lens: ``distortion_model`` (None: pinhole) and ``distortion``.

    It is the first frame's that carries a distortion model (a camera keeps its lens), with
    ``frames_distorted``, how many frames carried one.
    """
    distorted = [result.intrinsics for result in results
                 if result.intrinsics.distortion_model is not None]
    first = distorted[0] if distorted else None
    return {'distortion_model': None if first is None else first.distortion_model,
            'distortion': [] if first is None else list(first.distortion),
            'frames_distorted': len(distorted)}


def _without_depth(results: list[FrameResult]) -> list[FrameResult]:
    """Return ``results`` without their depth maps (not written; they would fill memory)."""
    return [dataclasses.replace(result, depth=None) for result in results]


def _push(engine: StreamingEngine, frame: SourceFrame) -> list[FrameResult]:
    try:
        return engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
    except InfiniHandError as exc:
        raise ConversionError(f'the engine refused the frame stamped {frame.timestamp_ns} '
                              f'({exc})') from exc


def _columns(collector: _Collector, push_of_slot: list[int], source_stamps: list[int],
             config: ConvertConfig) -> dict[str, np.ndarray]:
    """Return every feature column of the output frames."""
    missing = sorted(set(push_of_slot) - set(collector.values))
    if missing:
        raise ConversionError(f'the engine returned no result for frames {missing[:5]}')
    columns = {key: np.stack([collector.values[push][key] for push in push_of_slot])
               for key in RESULT_FEATURES}
    count = len(push_of_slot)
    later = np.minimum(np.arange(count) + config.dataset.action_offset, count - 1)
    columns[ACTION] = columns[STATE][later]
    columns[SOURCE_STAMP] = np.array(source_stamps, dtype=np.int64)[:, None]
    columns[FRAME_INDEX] = np.arange(count, dtype=np.int64)[:, None]
    columns[TIMESTAMP] = (np.arange(count) / config.fps)[:, None]
    return columns


def _fill_report(report: EpisodeReport, columns: dict[str, np.ndarray], collector: _Collector,
                 push_of_slot: list[int], source_stamps: list[int],
                 config: ConvertConfig) -> None:
    report.frames_out = len(push_of_slot)
    valid = columns[HAND_VALID].astype(bool)
    report.hands_valid = {side: int(valid[:, index].sum())
                          for index, side in enumerate(SIDE_NAMES)}
    invalid: dict[str, Counter] = {}
    for push in push_of_slot:
        for side, reason in collector.reasons[push].items():
            invalid.setdefault(side, Counter())[reason] += 1
    report.hands_invalid = {side: dict(reasons) for side, reasons in invalid.items()}
    flags = dict(zip(CAMERA_FLAG_NAMES, columns[CAMERA_FLAGS].astype(bool).T))
    report.camera_tracking = {
        'tracked': int(flags['tracked'].sum()),
        'predicted': int((~flags['tracked'] & ~flags['reinitialised']).sum()),
        'reinitialised': int(flags['reinitialised'].sum())}
    report.ba_failed_frames = int(flags['ba_failed'].sum())
    report.episode_refined_frames = int(flags['episode_refined'].sum())
    first = source_stamps[0]
    gaps = np.abs(np.array(source_stamps) - np.array(
        [output_time_ns(first, k, config.fps) for k in range(len(source_stamps))])) / NS_PER_S
    report.max_source_gap_s = float(gaps.max())
    report.source_gaps = int((gaps > config.max_source_gap_s).sum())
