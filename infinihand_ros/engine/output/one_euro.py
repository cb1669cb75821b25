"""The One-Euro filter (Casiez, Roussel and Vogel, CHI 2012) for arrays sampled at any times.

Per element: the speed ``dx = (x - x_prev) / dt`` is low-passed with cutoff ``d_cutoff_hz``;
the value is then low-passed with cutoff ``min_cutoff_hz + beta * |dx_hat|``. A first-order
low-pass with cutoff ``fc`` over a step ``dt`` has ``alpha = 1 / (1 + 1 / (2 pi fc dt))``. Slow
motion is smoothed strongly (little jitter), fast motion lightly (little lag).
"""

import math

from infinihand_ros.core.errors import InputError
import numpy as np


def smoothing_factor(cutoff_hz: float | np.ndarray, dt_s: float) -> float | np.ndarray:
    """Return the low-pass ``alpha`` of a cutoff (Hz) over a step of ``dt_s`` seconds."""
    return 1.0 / (1.0 + 1.0 / (2.0 * math.pi * np.asarray(cutoff_hz) * dt_s))


class OneEuroFilter:
    """One-Euro filter of arrays of one shape (not thread-safe)."""

    def __init__(self, min_cutoff_hz: float, beta: float, d_cutoff_hz: float) -> None:
        """Set the filter's parameters; the first sample passes through unchanged."""
        self.min_cutoff_hz = min_cutoff_hz
        self.beta = beta
        self.d_cutoff_hz = d_cutoff_hz
        self.reset()

    def reset(self) -> None:
        """Forget the past: the next sample passes through unchanged."""
        self._value: np.ndarray | None = None
        self._speed: np.ndarray | None = None
        self._time_s = 0.0

    def __call__(self, value: np.ndarray, time_s: float) -> np.ndarray:
        """Filter one sample taken at ``time_s`` seconds; return the filtered array.

        A sample not later than the previous one restarts the filter from it.

        Raises:
            InputError: when the shape differs from the previous samples'.

        """
        value = np.asarray(value, dtype=np.float64)
        if self._value is None or time_s <= self._time_s:
            self._value, self._speed, self._time_s = value.copy(), np.zeros_like(value), time_s
            return value.copy()
        if value.shape != self._value.shape:
            raise InputError(f'one-euro filter: sample of shape {value.shape} after samples of '
                             f'shape {self._value.shape}; reset() between streams')
        dt = time_s - self._time_s
        speed = (value - self._value) / dt
        self._speed = self._speed + smoothing_factor(self.d_cutoff_hz, dt) * (speed - self._speed)
        cutoff = self.min_cutoff_hz + self.beta * np.abs(self._speed)
        self._value = self._value + smoothing_factor(cutoff, dt) * (value - self._value)
        self._time_s = time_s
        return self._value.copy()
