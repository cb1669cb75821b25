"""Settings of the bag-to-dataset converter (``config/convert.yaml``), checked at load.

``convert`` -> ``engine`` (the engine settings profile, file and overrides) -> ``dataset`` (LeRobot
layout values) -> ``video`` (encoder) -> ``ray`` (``--ray`` workers). Command-line flags replace
single values afterwards.
"""

from dataclasses import dataclass
from dataclasses import field
import math
from pathlib import Path
from typing import Final

from infinihand_ros.convert.image_fit import LETTERBOX
from infinihand_ros.convert.image_fit import parse_video_size
from infinihand_ros.convert.image_fit import RESIZE_MODES
from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import load_config
from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.settings import parse_overrides
from infinihand_ros.engine.settings import PROFILES

CONVERT_SECTION: Final = 'convert'
#: PyAV encoders the writer accepts (H.264 and AV1, both in PyAV's wheels).
VIDEO_CODECS: Final = ('libx264', 'libsvtav1')


@dataclass(frozen=True)
class EngineChoice:
    """Which engine settings convert the episodes (section ``convert.engine``).

    Attributes:
        profile: the engine settings profile (``engine/settings.py``): 'offline' (windowed,
            with bundle adjustment; real recordings, MediaPipe hands) unless another is named.
        config: an engine settings file applied over the profile; '' for none.
        overrides: ``key=value`` engine settings applied last (as ``--set``).

    """

    profile: str = 'offline'
    config: str = ''
    overrides: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.profile not in PROFILES:
            raise ConfigError(f'convert.engine.profile must be one of {list(PROFILES)}, got '
                              f'{self.profile!r}')
        parse_overrides(self.overrides, 'convert.engine.overrides')


@dataclass(frozen=True)
class DatasetLayout:
    """LeRobot dataset values (section ``convert.dataset``).

    Attributes:
        robot_type: ``info.json`` robot_type.
        video_key: feature name of the ego video.
        chunks_size: files per ``chunk-NNN`` directory.
        invalid_fill: value written into the features of a hand that is not valid (its flag in
            ``hands.valid`` is False); NaN is allowed.
        action_offset: ``action`` is the state this many frames later.
        video_size: 'WxH' of every episode's video; '' for the existing dataset's, else the
            first input's. Inputs of another size are fitted to it (``image_fit``).
        resize: how they are fitted: 'letterbox' (scaled, padded black) or 'crop' (scaled,
            centre-cropped).

    """

    robot_type: str = 'hand'
    video_key: str = 'observation.images.ego'
    chunks_size: int = 1000
    invalid_fill: float = 0.0
    action_offset: int = 1
    video_size: str = ''
    resize: str = LETTERBOX

    def __post_init__(self) -> None:
        require_at_least('convert.dataset', 1, chunks_size=self.chunks_size,
                         action_offset=self.action_offset)
        parse_video_size(self.video_size, 'convert.dataset.video_size')
        if self.resize not in RESIZE_MODES:
            raise ConfigError(f'convert.dataset.resize must be one of {list(RESIZE_MODES)}, '
                              f'got {self.resize!r}')
        if '/' in self.video_key or not self.video_key:
            raise ConfigError(f'convert.dataset.video_key: LeRobot feature names are non-empty '
                              f'and hold no "/", got {self.video_key!r}')


@dataclass(frozen=True)
class VideoSettings:
    """Encoder of the episode videos (section ``convert.video``).

    Attributes:
        codec: 'libx264' (H.264) or 'libsvtav1' (AV1).
        pix_fmt: pixel format of the stream.
        crf: constant rate factor (quality; lower is better).
        gop: keyframe interval in frames.
        preset: encoder speed preset.

    """

    codec: str = 'libx264'
    pix_fmt: str = 'yuv420p'
    crf: int = 23
    gop: int = 2
    preset: str = 'veryfast'

    def __post_init__(self) -> None:
        if self.codec not in VIDEO_CODECS:
            raise ConfigError(f'convert.video.codec must be one of {list(VIDEO_CODECS)}, got '
                              f'{self.codec!r}')
        require_at_least('convert.video', 1, gop=self.gop)
        require_at_least('convert.video', 0, crf=self.crf)


@dataclass(frozen=True)
class RaySettings:
    """How ``--ray`` spreads the inputs over a Ray cluster (section ``convert.ray``).

    Attributes:
        workers: converter actors, each holding one engine; 0 = one per ``gpus_per_worker``
            GPUs when the cluster has GPUs, else one per ``cpus_per_worker`` CPUs.
        cpus_per_worker: CPUs reserved by each actor.
        gpus_per_worker: GPUs reserved by each actor on a cluster with GPUs (run the engine on
            them with ``engine.device: cuda`` in the engine file).
        local_cpus: CPUs of the local Ray instance that ``--ray`` without an address starts;
            None for all of this machine's.

    """

    workers: int = 0
    cpus_per_worker: float = 1.0
    gpus_per_worker: float = 1.0
    local_cpus: int | None = None

    def __post_init__(self) -> None:
        require_at_least('convert.ray', 0, workers=self.workers)
        require_positive('convert.ray', cpus_per_worker=self.cpus_per_worker,
                         gpus_per_worker=self.gpus_per_worker)
        if self.local_cpus is not None:
            require_at_least('convert.ray', 1, local_cpus=self.local_cpus)


@dataclass(frozen=True)
class ConvertConfig:
    """Everything the converter needs besides its inputs and output.

    Attributes:
        fps: output frame rate (Hz, whole number); timestamps are ``frame_index / fps``.
        task: task string of every episode; '' to read ``<input>.task.txt`` beside each input,
            else ``default_task``.
        default_task: task of inputs with neither ``task`` nor a sidecar file.
        episode_max_s: split each input into episodes of at most this many seconds; None for
            one episode per input.
        max_source_gap_s: output frames farther than this from their nearest source frame are
            counted as gaps in the report.
        engine: the engine to run.
        dataset: LeRobot layout values.
        video: the video encoder.
        estimates_bag: also write an MCAP bag of the estimates per episode.
        estimates_path_length: camera positions in the bag's camera-path marker (the newest
            are kept, as the node's ``outputs.path_length``).
        ray: the workers of ``--ray``.

    """

    fps: int = 10
    task: str = ''
    default_task: str = 'demonstration'
    episode_max_s: float | None = None
    max_source_gap_s: float = 0.5
    engine: EngineChoice = field(default_factory=EngineChoice)
    dataset: DatasetLayout = field(default_factory=DatasetLayout)
    video: VideoSettings = field(default_factory=VideoSettings)
    estimates_bag: bool = True
    estimates_path_length: int = 1000
    ray: RaySettings = field(default_factory=RaySettings)

    def __post_init__(self) -> None:
        require_at_least('convert', 1, fps=self.fps,
                         estimates_path_length=self.estimates_path_length)
        require_positive('convert', max_source_gap_s=self.max_source_gap_s)
        if self.episode_max_s is not None and not (
                math.isfinite(self.episode_max_s) and self.episode_max_s > 0):
            raise ConfigError(f'convert.episode_max_s must be a positive number of seconds or '
                              f'null, got {self.episode_max_s!r}')
        if not self.default_task:
            raise ConfigError('convert.default_task must not be empty')


def load_convert_config(path: str | Path | None = None) -> ConvertConfig:
    """Load ``config/convert.yaml`` (or ``path``).

    Raises:
        ConfigError: for a missing file, unknown keys, wrong types or values (naming the key).

    """
    path = Path(path) if path is not None else config_dir() / 'convert.yaml'
    return load_config(path, CONVERT_SECTION, ConvertConfig)
