"""Resampling a stream of stamped items to a fixed frame rate, streamed (one item lookahead).

Output frame ``k`` has the exact timestamp ``k / fps`` seconds from the first source stamp and
takes the source item nearest to that time (ties go to the earlier item). Output frames run
from the first source stamp to the last one: ``floor((last - first) * fps) + 1`` frames. A
source item is used by several output frames when the source is slower than ``fps`` and by none
when it is faster; the chosen item's own stamp stays with each output frame.
"""

from collections.abc import Iterable
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Generic, TypeVar

from infinihand_ros.core.units import NS_PER_S

ItemT = TypeVar('ItemT')


@dataclass(frozen=True)
class ResampledFrame(Generic[ItemT]):
    """One output frame.

    Attributes:
        frame_index: 0-based output index.
        timestamp_s: ``frame_index / fps`` (episode-relative seconds).
        source_index: 0-based index of the chosen source item.
        source_stamp_ns: the chosen item's stamp.
        item: the chosen item.

    """

    frame_index: int
    timestamp_s: float
    source_index: int
    source_stamp_ns: int
    item: ItemT


def output_time_ns(first_ns: int, frame_index: int, fps: int) -> int:
    """Return the source-clock time of output frame ``frame_index`` (integer nanoseconds)."""
    return first_ns + (frame_index * NS_PER_S) // fps


def resample(stamped: Iterable[tuple[int, ItemT]], fps: int) -> Iterator[ResampledFrame[ItemT]]:
    """Yield the output frames of increasing-stamp ``(stamp_ns, item)`` pairs at ``fps``.

    Raises:
        ValueError: for ``fps < 1`` or stamps that do not increase.

    """
    if fps < 1:
        raise ValueError(f'fps must be a whole number >= 1, got {fps}')
    first: int | None = None
    previous: tuple[int, int, ItemT] | None = None  # (source index, stamp, item)
    frame_index = 0
    for source_index, (stamp, item) in enumerate(stamped):
        if previous is None:
            first = stamp
        elif stamp <= previous[1]:
            raise ValueError(f'resample: stamps must increase, got {stamp} after {previous[1]}')
        else:
            # Every output time before the midpoint of the two stamps belongs to ``previous``.
            while 2 * output_time_ns(first, frame_index, fps) <= previous[1] + stamp:
                yield _frame(frame_index, fps, previous)
                frame_index += 1
        previous = (source_index, stamp, item)
    if previous is not None:
        while output_time_ns(first, frame_index, fps) <= previous[1]:
            yield _frame(frame_index, fps, previous)
            frame_index += 1


def _frame(frame_index: int, fps: int, chosen: tuple[int, int, ItemT]) -> ResampledFrame[ItemT]:
    source_index, stamp, item = chosen
    return ResampledFrame(frame_index, frame_index / fps, source_index, stamp, item)
