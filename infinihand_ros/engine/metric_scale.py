"""Metric scale of the camera trajectory, estimated online from the hands (MODEL.md "Scale").

The geometry branch predicts depth and camera translations up to an unknown scale; hands are
metric (MANO sizes + least-squares projection). Each observation is the ratio of a hand's metric
depth to the model's depth at the hand's pixels; the estimate is the median of the most recent
ratios, with a MAD-based standard error as its uncertainty.
"""

from collections import deque
from dataclasses import dataclass
import threading
from typing import Final

from infinihand_ros.core.errors import ConfigError
import numpy as np

#: Converts a median absolute deviation into a normal standard deviation.
MAD_TO_SIGMA: Final = 1.4826
#: Standard error of a median in units of sigma / sqrt(n), for normal data (sqrt(pi / 2)).
MEDIAN_STANDARD_ERROR: Final = 1.2533


@dataclass(frozen=True)
class MetricScaleConfig:
    """Settings of the running scale estimate (section ``metric_scale`` of the engine config).

    Attributes:
        history: number of most recent ratios kept.
        min_samples: ratios needed before the estimate replaces ``initial``.
        initial: scale reported until then (1.0: the model's own units).
        min_ratio: ratios below this are rejected as outliers.
        max_ratio: ratios above this are rejected as outliers.

    """

    history: int = 300
    min_samples: int = 5
    initial: float = 1.0
    min_ratio: float = 1e-3
    max_ratio: float = 1e3

    def __post_init__(self) -> None:
        if self.history < 1 or not 1 <= self.min_samples <= self.history:
            raise ConfigError(f'metric_scale: need history >= min_samples >= 1, got '
                              f'{self.history} and {self.min_samples}')
        if not 0 < self.min_ratio < self.initial < self.max_ratio:
            raise ConfigError(f'metric_scale: need 0 < min_ratio < initial < max_ratio, got '
                              f'{self.min_ratio}, {self.initial}, {self.max_ratio}')


@dataclass(frozen=True)
class ScaleEstimate:
    """Current metric scale: metres per model unit, its standard error and the sample count."""

    scale: float
    uncertainty: float
    samples: int


class MetricScaleEstimator:
    """Robust running estimate of metres per model depth unit (safe to share between threads)."""

    def __init__(self, config: MetricScaleConfig | None = None) -> None:
        """Start with no observations."""
        self.config = config or MetricScaleConfig()
        self._ratios: deque[float] = deque(maxlen=self.config.history)
        self._lock = threading.Lock()

    def reset(self) -> None:
        """Forget every observation."""
        with self._lock:
            self._ratios.clear()

    def observe(self, metric_depths: np.ndarray, model_depths: np.ndarray) -> int:
        """Add ratios of metric hand depths to model depths; return how many were kept.

        Args:
            metric_depths: (N,) depths (m) of hands from the hand branch, one per hand (e.g. the
                median over its visible joints).
            model_depths: (N,) depths (model units) of the depth head at the same pixels.

        Non-finite, non-positive and out-of-range ratios are skipped.

        """
        metric = np.asarray(metric_depths, dtype=np.float64).reshape(-1)
        model = np.asarray(model_depths, dtype=np.float64).reshape(-1)
        if metric.shape != model.shape:
            raise ValueError(f'metric_depths {metric.shape} and model_depths {model.shape} '
                             'must have the same length')
        with np.errstate(divide='ignore', invalid='ignore'):
            ratios = metric / model
        keep = (np.isfinite(ratios) & (metric > 0) & (model > 0)
                & (ratios > self.config.min_ratio) & (ratios < self.config.max_ratio))
        with self._lock:
            self._ratios.extend(ratios[keep].tolist())
        return int(keep.sum())

    def estimate(self) -> ScaleEstimate:
        """Return the current estimate; ``initial`` with infinite uncertainty until enough data."""
        with self._lock:
            ratios = np.array(self._ratios, dtype=np.float64)
        count = len(ratios)
        if count < self.config.min_samples:
            return ScaleEstimate(self.config.initial, float('inf'), count)
        median = float(np.median(ratios))
        spread = MAD_TO_SIGMA * float(np.median(np.abs(ratios - median)))
        return ScaleEstimate(median, MEDIAN_STANDARD_ERROR * spread / np.sqrt(count), count)
