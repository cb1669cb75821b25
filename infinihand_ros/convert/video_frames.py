"""Frames of a plain video file (mp4, mkv, ...) decoded with PyAV, streamed.

Stamps are the frames' presentation times in nanoseconds from the stream start; every frame
carries the intrinsics given on the command line, or None (the model predicts the field of
view). Frames without a presentation time are skipped and counted.
"""

from collections.abc import Iterator
from pathlib import Path

import av
from infinihand_ros.convert.frame_log import FrameLog
from infinihand_ros.convert.source_frames import SourceFrame
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.units import NS_PER_S

NO_PTS = 'video frame without a presentation time'


def read_video_frames(path: Path, intrinsics: Intrinsics | None,
                      log: FrameLog) -> Iterator[SourceFrame]:
    """Yield the RGB frames of the first video stream of ``path``.

    Args:
        path: a video file PyAV (FFmpeg) can decode.
        intrinsics: the camera's intrinsics, or None; ignored (counted) when they are for
            another image size.
        log: receives the frames read, skipped and warnings.

    Raises:
        InputError: when the file cannot be opened, has no video stream or is corrupt.

    """
    try:
        container = av.open(str(path))
    except (av.FFmpegError, OSError) as exc:
        raise InputError(f'video {path} cannot be opened ({exc}); pass an mp4/mkv file FFmpeg '
                         'can decode') from exc
    with container:
        if not container.streams.video:
            raise InputError(f'video {path} has no video stream')
        stream = container.streams.video[0]
        try:
            for frame in container.decode(stream):
                log.read += 1
                if frame.pts is None or frame.time is None:
                    log.skip(NO_PTS)
                    continue
                rgb = frame.to_ndarray(format='rgb24')
                yield SourceFrame(round(frame.time * NS_PER_S), rgb, matching_intrinsics(
                    intrinsics, rgb.shape[1], rgb.shape[0], path, log))
        except av.FFmpegError as exc:
            raise InputError(f'video {path}: decoding failed after {log.read} frames ({exc}); '
                             'the file may be truncated or corrupt') from exc


def matching_intrinsics(intrinsics: Intrinsics | None, width: int, height: int, path: Path,
                        log: FrameLog) -> Intrinsics | None:
    """Return the given intrinsics where they fit a width x height frame, else None (counted)."""
    if intrinsics is None:
        log.warn('no intrinsics given (--intrinsics): predicted by the model')
        return None
    if (intrinsics.width, intrinsics.height) != (width, height):
        log.warn(f'--intrinsics are for {intrinsics.width}x{intrinsics.height}, {path.name} '
                 f'is {width}x{height}: intrinsics predicted')
        return None
    return intrinsics
