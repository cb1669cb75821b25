"""Tests of engine/timestamps.py: integer, int64, increasing stamps; late or restarted."""

from infinihand_ros.core.errors import InputError
from infinihand_ros.engine.timestamps import check_timestamp
from infinihand_ros.engine.timestamps import stamp_step
from infinihand_ros.engine.timestamps import StampStep
import numpy as np
import pytest


def test_integers_and_numpy_integers_pass() -> None:
    """Python and numpy integers come back as int."""
    assert check_timestamp(5, None) == 5
    value = check_timestamp(np.int64(7), 5)
    assert value == 7 and type(value) is int


@pytest.mark.parametrize('stamp', [None, float('nan'), 1.5, 2.0, '10', True, np.float64(3.0)])
def test_non_integers_are_refused(stamp) -> None:
    """None, NaN, floats, strings and booleans raise InputError asking for integer ns."""
    with pytest.raises(InputError, match='integer nanoseconds'):
        check_timestamp(stamp, None)


def test_values_beyond_int64_are_refused() -> None:
    """2**63 does not fit a bag's stamp."""
    with pytest.raises(InputError, match='int64'):
        check_timestamp(2 ** 63, None)


def test_duplicate_and_backward_stamps_are_refused() -> None:
    """A repeated or earlier stamp names the previous one and the fix."""
    with pytest.raises(InputError, match='a duplicate of the previous'):
        check_timestamp(10, 10)
    with pytest.raises(InputError, match='earlier than the previous frame.s 10 ns'):
        check_timestamp(9, 10)


NS_PER_S = 1_000_000_000
LAST = 100 * NS_PER_S


@pytest.mark.parametrize(('stamp', 'last', 'step'), [
    (5, None, 'next'),  # the first frame
    (LAST + 1, LAST, 'next'),
    (LAST + 3600 * NS_PER_S, LAST, 'next'),  # a jump ahead continues the stream
    (LAST, LAST, 'out_of_order'),  # repeated
    (LAST - 1, LAST, 'out_of_order'),  # late
    (LAST - NS_PER_S, LAST, 'out_of_order'),  # exactly the restart gap back: still late
    (LAST - NS_PER_S - 1, LAST, 'restart'),  # beyond it: a new stream
    (0, LAST, 'restart'),  # a replay looping back to its start
])
def test_stamp_step_tells_next_late_and_restart(stamp: int, last: int | None, step: str) -> None:
    """Later: next; back by at most the gap: out of order; further back: restart."""
    assert stamp_step(stamp, last, NS_PER_S) == step


def test_normal_stamps_after_a_far_future_one_restart() -> None:
    """A far-future stamp is taken; the normal ones after it are far before it: a restart."""
    future = LAST + 3600 * NS_PER_S
    assert stamp_step(future, LAST, NS_PER_S) is StampStep.NEXT
    assert stamp_step(LAST + NS_PER_S // 10, future, NS_PER_S) is StampStep.RESTART


def test_a_zero_restart_gap_never_restarts() -> None:
    """restart_after_ns 0: every stamp not after the last one is out of order."""
    assert stamp_step(0, LAST, 0) is StampStep.OUT_OF_ORDER
    assert stamp_step(LAST + 1, LAST, 0) is StampStep.NEXT
