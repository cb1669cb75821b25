"""Source frames of one input and the documented rule for bad stamps and size changes.

Rule (the same for bags and videos): a frame whose stamp equals the previous kept frame's is
dropped as a duplicate; one whose stamp is earlier is dropped as out of order; one whose size
differs from the first kept frame's is dropped (the engine runs one size per stream). Each drop
is counted with its reason in the episode's ``FrameLog``; nothing is fitted silently.
"""

from collections.abc import Iterable
from collections.abc import Iterator
from dataclasses import dataclass

from infinihand_ros.convert.frame_log import FrameLog
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.units import NS_PER_S
import numpy as np

DUPLICATE_STAMP = 'duplicate stamp (same as the previous frame)'
BACKWARD_STAMP = 'stamp earlier than the previous frame (out of order)'


@dataclass(frozen=True)
class SourceFrame:
    """One decoded source frame.

    Attributes:
        timestamp_ns: the image's stamp (header stamp for bags, presentation time for videos).
        rgb: (H, W, 3) uint8 RGB.
        intrinsics: the camera's intrinsics for this image size, or None (predicted).

    """

    timestamp_ns: int
    rgb: np.ndarray
    intrinsics: Intrinsics | None


def checked_frames(frames: Iterable[SourceFrame], log: FrameLog) -> Iterator[SourceFrame]:
    """Yield the frames that keep stamps increasing and the size constant; count the rest."""
    last_stamp: int | None = None
    size: tuple[int, int] | None = None
    for frame in frames:
        frame_size = (frame.rgb.shape[1], frame.rgb.shape[0])
        if last_stamp is not None and frame.timestamp_ns <= last_stamp:
            log.skip(DUPLICATE_STAMP if frame.timestamp_ns == last_stamp else BACKWARD_STAMP)
            continue
        if size is not None and frame_size != size:
            log.skip(f"image size {frame_size[0]}x{frame_size[1]} differs from the episode's "
                     f'{size[0]}x{size[1]}')
            continue
        size = frame_size
        last_stamp = frame.timestamp_ns
        yield frame


def split_windows(frames: Iterable[SourceFrame],
                  max_s: float | None) -> Iterator[tuple[int, SourceFrame]]:
    """Yield (window index, frame): windows of ``max_s`` seconds from the first stamp.

    With ``max_s`` None every frame is in window 0 (one episode per input).
    """
    first: int | None = None
    for frame in frames:
        if first is None:
            first = frame.timestamp_ns
        window = 0 if max_s is None else int((frame.timestamp_ns - first) // (max_s * NS_PER_S))
        yield window, frame
