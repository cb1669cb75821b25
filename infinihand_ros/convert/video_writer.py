"""Episode videos encoded frame by frame with PyAV (H.264 or AV1 in mp4).

Frame ``k`` gets presentation time ``k / fps`` exactly (time base ``1/fps``), as LeRobot looks
video frames up by timestamp. yuv420p needs even sizes: an odd width or height gets one column
or row repeated at the right or bottom edge (the principal point does not move).
"""

from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import av
from infinihand_ros.convert.config import VideoSettings
from infinihand_ros.core.errors import InputError
import numpy as np


@dataclass(frozen=True)
class VideoInfo:
    """What was written: size in pixels (after padding), frame count and codec."""

    width: int
    height: int
    frames: int
    codec: str
    pix_fmt: str


def _even(size: int) -> int:
    return size + size % 2


def _options(settings: VideoSettings) -> dict[str, str]:
    return {'crf': str(settings.crf), 'g': str(settings.gop), 'preset': settings.preset}


class EpisodeVideoWriter:
    """Context manager writing one mp4; the size is fixed by the first frame."""

    def __init__(self, path: Path, fps: int, settings: VideoSettings) -> None:
        """Open ``path`` for writing (the stream is created with the first frame)."""
        self.path = Path(path)
        self._fps = fps
        self._settings = settings
        self._container = av.open(str(self.path), mode='w')
        self._stream: av.VideoStream | None = None
        self._size: tuple[int, int] | None = None
        self._frames = 0

    def _open_stream(self, width: int, height: int) -> av.VideoStream:
        stream = self._container.add_stream(self._settings.codec, rate=self._fps,
                                            options=_options(self._settings))
        stream.width, stream.height = _even(width), _even(height)
        stream.pix_fmt = self._settings.pix_fmt
        stream.time_base = Fraction(1, self._fps)
        return stream

    def write(self, rgb: np.ndarray) -> None:
        """Encode the next frame: (H, W, 3) uint8 RGB of the first frame's size.

        Raises:
            InputError: for another size or dtype.

        """
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
            raise InputError(f'video {self.path}: expected (H, W, 3) uint8, got {rgb.shape} '
                             f'{rgb.dtype}')
        height, width = rgb.shape[:2]
        if self._stream is None:
            self._stream = self._open_stream(width, height)
            self._size = (width, height)
        elif (width, height) != self._size:
            raise InputError(f'video {self.path}: frame {width}x{height}, but the video is '
                             f'{self._size[0]}x{self._size[1]}')
        padded = np.pad(rgb, ((0, height % 2), (0, width % 2), (0, 0)), mode='edge')
        frame = av.VideoFrame.from_ndarray(padded, format='rgb24')
        frame.pts = self._frames
        frame.time_base = Fraction(1, self._fps)
        for packet in self._stream.encode(frame):
            self._container.mux(packet)
        self._frames += 1

    def close(self) -> VideoInfo:
        """Flush the encoder, close the file and return what was written.

        Raises:
            InputError: when no frame was written.

        """
        try:
            if self._stream is None:
                raise InputError(f'video {self.path}: no frame was written')
            for packet in self._stream.encode(None):
                self._container.mux(packet)
        finally:
            self._container.close()
        return VideoInfo(self._stream.width, self._stream.height, self._frames,
                         self._settings.codec, self._settings.pix_fmt)

    def __enter__(self) -> 'EpisodeVideoWriter':
        """Return the writer."""
        return self

    def __exit__(self, exc_type: object, exc: object, traceback: object) -> None:
        """Close the file when the block failed (a successful block calls ``close``)."""
        if exc_type is not None:
            self._container.close()
