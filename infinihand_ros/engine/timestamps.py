"""Frame timestamps: integer nanoseconds, strictly increasing within a stream.

Results carry their image's stamp, BA keys its corrections by stamp and the pose track blends
corrections by stamp, so a stream's stamps must be integers that increase from frame to frame.
A live caller decides with ``stamp_step`` what a stamp that does not increase means: a late or
repeated frame to skip, or (far earlier) the start of a new stream.
"""

from enum import StrEnum
import numbers

from infinihand_ros.core.errors import InputError
import numpy as np

INT64_MIN = int(np.iinfo(np.int64).min)
INT64_MAX = int(np.iinfo(np.int64).max)


def check_timestamp(stamp: object, previous: int | None) -> int:
    """Return ``stamp`` as an int, or raise InputError saying what is wrong and what to do.

    Args:
        stamp: the frame's stamp in nanoseconds (a Python or numpy integer).
        previous: the stream's previous stamp, or None for the first frame.

    Raises:
        InputError: for None, booleans, floats (NaN included), other types, values outside
            int64, and stamps that do not increase (duplicates or backwards steps).

    """
    if isinstance(stamp, (bool, np.bool_)) or not isinstance(stamp, numbers.Integral):
        raise InputError(f'frame timestamp: expected integer nanoseconds, got '
                         f'{type(stamp).__name__} {stamp!r}; convert stamps with '
                         'sec * 1_000_000_000 + nanosec')
    value = int(stamp)
    if not INT64_MIN <= value <= INT64_MAX:
        raise InputError(f'frame timestamp: {value} ns does not fit in int64')
    if previous is not None and value <= previous:
        kind = 'a duplicate of' if value == previous else 'earlier than'
        raise InputError(f"frame timestamp: {value} ns is {kind} the previous frame's "
                         f'{previous} ns; stamps must increase within a stream (drop the frame, '
                         'or reset() the engine to start a new stream)')
    return value


class StampStep(StrEnum):
    """How a frame's stamp follows the last accepted one (compares equal to its value)."""

    NEXT = 'next'  # later: the frame continues the stream
    OUT_OF_ORDER = 'out_of_order'  # not later, by at most the restart gap: late or repeated
    RESTART = 'restart'  # earlier by more than the restart gap: a new stream starts with it


def stamp_step(stamp_ns: int, last_ns: int | None, restart_after_ns: int) -> StampStep:
    """Return whether a frame continues the stream, is out of order, or starts a new stream.

    Args:
        stamp_ns: the frame's stamp, ns.
        last_ns: the stamp of the stream's last accepted frame, ns; None before the first.
        restart_after_ns: a stamp earlier than ``last_ns`` by more than this starts a new
            stream (a replay looping, a camera driver restarting, normal stamps after a
            far-future one), ns; 0: never (every stamp not after ``last_ns`` is out of order).

    """
    if last_ns is None or stamp_ns > last_ns:
        return StampStep.NEXT
    if restart_after_ns > 0 and last_ns - stamp_ns > restart_after_ns:
        return StampStep.RESTART
    return StampStep.OUT_OF_ORDER
