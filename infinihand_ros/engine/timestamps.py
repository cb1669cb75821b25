"""Frame timestamps: integer nanoseconds, strictly increasing within a stream.

Results carry their image's stamp, BA keys its corrections by stamp and the pose track blends
corrections by stamp, so a stream's stamps must be integers that increase from frame to frame.
"""

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
