"""Tests of engine/timestamps.py: integer, int64, strictly increasing stamps."""

from infinihand_ros.core.errors import InputError
from infinihand_ros.engine.timestamps import check_timestamp
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
