"""The One-Euro filter (engine/output/one_euro.py), against values worked out by hand."""

import math

from infinihand_ros.core.errors import InputError
from infinihand_ros.engine.output.one_euro import OneEuroFilter
from infinihand_ros.engine.output.one_euro import smoothing_factor
import numpy as np
import pytest


def test_smoothing_factor_formula() -> None:
    """The factor is 1 / (1 + 1 / (2 pi fc dt)): fc = 1/(2 pi) Hz, dt = 1 s gives 0.5."""
    assert smoothing_factor(1.0 / (2.0 * math.pi), 1.0) == pytest.approx(0.5)
    assert smoothing_factor(1.0, 0.1) == pytest.approx(1.0 / (1.0 + 1.0 / (0.2 * math.pi)))


def test_beta_zero_is_a_fixed_low_pass() -> None:
    """With beta 0 each step moves alpha(min_cutoff) of the way to the new value."""
    cutoff = 1.0 / (2.0 * math.pi)  # alpha 0.5 at dt = 1 s
    one_euro = OneEuroFilter(cutoff, 0.0, 1.0)
    assert one_euro(np.array([0.0]), 0.0)[0] == 0.0
    assert one_euro(np.array([1.0]), 1.0)[0] == pytest.approx(0.5)
    assert one_euro(np.array([1.0]), 2.0)[0] == pytest.approx(0.75)


def test_beta_raises_the_cutoff_with_speed() -> None:
    """Speed 1/s, d-alpha 0.5: dx_hat 0.5, cutoff fc + beta*0.5; the value follows it."""
    d_cutoff = 1.0 / (2.0 * math.pi)
    one_euro = OneEuroFilter(d_cutoff, 2.0 * math.pi, d_cutoff)
    one_euro(np.array([0.0]), 0.0)
    cutoff = d_cutoff + 2.0 * math.pi * 0.5
    alpha = 1.0 / (1.0 + 1.0 / (2.0 * math.pi * cutoff))
    assert one_euro(np.array([1.0]), 1.0)[0] == pytest.approx(alpha)
    assert alpha > 0.5


def test_reset_and_time_going_back_restart() -> None:
    """After reset (or a stamp not after the last) the sample passes unchanged."""
    one_euro = OneEuroFilter(1.0, 0.0, 1.0)
    one_euro(np.zeros(3), 0.0)
    np.testing.assert_array_equal(one_euro(np.ones(3), 0.0), np.ones(3))
    one_euro.reset()
    np.testing.assert_array_equal(one_euro(np.full(3, 5.0), 1.0), np.full(3, 5.0))
    with pytest.raises(InputError, match='shape'):
        one_euro(np.zeros(2), 2.0)
