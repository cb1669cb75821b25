"""Fitting an input's frames to the dataset's video size, with the exact pixel mapping.

A dataset has one video size (``--video-size WxH``, else the existing dataset's, else the first
input's). Frames of another size are scaled (aspect kept) and either letterboxed (padded black,
nothing lost) or centre-cropped (filled, edges lost) to it before the engine sees them, so every
2D output (intrinsics, keypoints, boxes) is in the dataset's pixels by construction. Given
intrinsics are mapped with the same ``FrameMapping`` as the pixels (pixel centres at integers:
``dataset = scale * source + offset``), and the mapping is kept in the episode's record.
A frame whose size differs only by the one row or column the video writer pads (odd sizes) is
left alone: the padding does not move the principal point.
"""

from dataclasses import replace
from typing import Any, Final

import cv2
from infinihand_ros.convert.source_frames import SourceFrame
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.frame_input import FrameMapping
from infinihand_ros.engine.frame_input import letterbox
import numpy as np

LETTERBOX: Final = 'letterbox'
CROP: Final = 'crop'
RESIZE_MODES: Final = (LETTERBOX, CROP)


def parse_video_size(text: str, name: str = 'video_size') -> tuple[int, int] | None:
    """Return (width, height) of ``'WxH'``, or None for ''.

    Raises:
        ConfigError: for anything but two integers >= 2 joined by 'x'.

    """
    if not text:
        return None
    parts = text.lower().split('x')
    try:
        width, height = (int(part) for part in parts)
    except ValueError:
        width = height = 0
    if len(parts) != 2 or width < 2 or height < 2:
        raise ConfigError(f'{name}: expected WIDTHxHEIGHT in pixels (e.g. 640x480), got '
                          f'{text!r}')
    return width, height


def _even(size: int) -> int:
    return size + size % 2


def needs_fit(source_size: tuple[int, int], target: tuple[int, int]) -> bool:
    """Return whether frames of ``source_size`` must be resized for videos of ``target``."""
    return (_even(source_size[0]), _even(source_size[1])) != (_even(target[0]),
                                                              _even(target[1]))


def crop_to(image: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, FrameMapping]:
    """Scale ``image`` to cover ``size`` (width, height), aspect kept, and centre-crop it."""
    height, width = image.shape[:2]
    scale = max(size[0] / width, size[1] / height)
    new_width = max(size[0], int(round(width * scale)))
    new_height = max(size[1], int(round(height * scale)))
    interpolation = cv2.INTER_AREA if scale < 1.0 else cv2.INTER_LINEAR
    resized = cv2.resize(image, (new_width, new_height), interpolation=interpolation)
    left, top = (new_width - size[0]) // 2, (new_height - size[1]) // 2
    scale_x, scale_y = new_width / width, new_height / height
    mapping = FrameMapping(scale_x=scale_x, scale_y=scale_y,
                           offset_x=0.5 * scale_x - 0.5 - left,
                           offset_y=0.5 * scale_y - 0.5 - top, source_size=(width, height),
                           model_size=size, content_box=(0, 0, size[0], size[1]))
    return np.ascontiguousarray(resized[top:top + size[1], left:left + size[0]]), mapping


def fit_frame(frame: SourceFrame, size: tuple[int, int], mode: str
              ) -> tuple[SourceFrame, FrameMapping]:
    """Return ``frame`` resized to ``size`` by ``mode`` and the mapping that was applied.

    Args:
        frame: a source frame (its intrinsics, when given, are for its own size).
        size: (width, height) of the dataset's video.
        mode: 'letterbox' or 'crop'.

    Raises:
        ConfigError: for an unknown mode.

    """
    if mode == LETTERBOX:
        rgb, mapping = letterbox(frame.rgb, size)
    elif mode == CROP:
        rgb, mapping = crop_to(frame.rgb, size)
    else:
        raise ConfigError(f'resize mode must be one of {list(RESIZE_MODES)}, got {mode!r}')
    intrinsics = (None if frame.intrinsics is None
                  else mapping.intrinsics_to_model(frame.intrinsics))
    return replace(frame, rgb=rgb, intrinsics=intrinsics), mapping


def mapping_record(mode: str, mapping: FrameMapping) -> dict[str, Any]:
    """Return the mapping as the episode record keeps it (dataset px = scale * source + offset)."""
    return {'mode': mode, 'source_size': list(mapping.source_size),
            'video_size': list(mapping.model_size),
            'scale': [mapping.scale_x, mapping.scale_y],
            'offset': [mapping.offset_x, mapping.offset_y],
            'content_box': list(mapping.content_box)}


class FrameFitter:
    """Fits the frames of one input to the dataset's video size; keeps what it did.

    Attributes:
        size: (width, height) of the dataset's video, or None (frames are kept as they are).
        mode: 'letterbox' or 'crop'.
        record: the mapping of the frames seen (``mapping_record``; scale 1 and offset 0 when
            they needed no fitting), or None before the first frame.

    """

    def __init__(self, size: tuple[int, int] | None, mode: str) -> None:
        """Fit to ``size`` by ``mode``."""
        self.size = size
        self.mode = mode
        self.record: dict[str, Any] | None = None

    def fit(self, frame: SourceFrame) -> SourceFrame:
        """Return ``frame`` fitted to the dataset's size (the same frame when it fits)."""
        source = (frame.rgb.shape[1], frame.rgb.shape[0])
        if self.size is None or not needs_fit(source, self.size):
            if self.record is None:
                self.record = {'mode': 'none', 'source_size': list(source),
                               'video_size': [_even(source[0]), _even(source[1])],
                               'scale': [1.0, 1.0], 'offset': [0.0, 0.0],
                               'content_box': [0, 0, source[0], source[1]]}
            return frame
        fitted, mapping = fit_frame(frame, self.size, self.mode)
        if self.record is None:
            self.record = mapping_record(self.mode, mapping)
        return fitted
