"""Metric scale of the camera trajectory, estimated online from the hands (MODEL.md "Scale").

The geometry branch predicts depth and camera translations up to an unknown scale; hands are
metric (MANO sizes + least-squares projection). Each observation is the ratio of a hand's metric
depth to the model's depth at the hand's pixels; the estimate is the median of the most recent
ratios, with a MAD-based standard error as its uncertainty. ``hand_depth_ratios`` computes the
observations from the hand branch's joints and the depth head's map.
"""

from collections import deque
from dataclasses import dataclass
import threading
from typing import Final

from infinihand_ros.core.errors import ConfigError
import numpy as np
import torch

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
        sample_interval: once ``min_samples`` ratios are held (the warm-up), the engine takes a
            frame's hands as samples on every this-many-th frame and on frames whose depth it
            computes anyway (the depth head runs only where a depth is used); 1: every frame.
        hand_depth_correction: every ratio is multiplied by this; it corrects a depth head that
            places hands too far (> 1) or too near (< 1) relative to the rest of the scene.
            None: the checkpoint's measured value (``scale_calibration.json``; 1 without one).

    """

    history: int = 300
    min_samples: int = 5
    initial: float = 1.0
    min_ratio: float = 1e-3
    max_ratio: float = 1e3
    sample_interval: int = 5
    hand_depth_correction: float | None = None

    def __post_init__(self) -> None:
        correction = self.hand_depth_correction
        if correction is not None and not (np.isfinite(correction) and correction > 0):
            raise ConfigError(f'metric_scale.hand_depth_correction must be a finite number > 0 '
                              f'or null, got {correction}')
        if self.history < 1 or not 1 <= self.min_samples <= self.history:
            raise ConfigError(f'metric_scale: need history >= min_samples >= 1, got '
                              f'{self.history} and {self.min_samples}')
        if self.sample_interval < 1:
            raise ConfigError(f'metric_scale.sample_interval must be >= 1 frame, got '
                              f'{self.sample_interval}')
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


def hand_depth_ratios(depth: torch.Tensor, frame_index: torch.Tensor, joints_2d: torch.Tensor,
                      joints_depth: torch.Tensor) -> torch.Tensor:
    """Return per hand the median of metric joint depth / model depth at the joint's pixel.

    Joints outside the image or with non-positive depths are left out (NaN when none is left);
    the median over the 21 joints makes occluded joints and the limb radius matter little.

    Args:
        depth: (F, H, W) model depth maps of the frames (model units).
        frame_index: (N,) frame of each hand.
        joints_2d: (N, 21, 2) joint pixels (u, v) in the depth maps' image.
        joints_depth: (N, 21) metric joint depths (m) from the hand branch.

    Returns:
        (N,) ratios, metres per model unit.

    """
    height, width = depth.shape[-2:]
    pixels = joints_2d.round().long()
    inside = ((pixels[..., 0] >= 0) & (pixels[..., 0] < width) & (pixels[..., 1] >= 0)
              & (pixels[..., 1] < height))
    columns = pixels[..., 0].clamp(0, width - 1)
    rows = pixels[..., 1].clamp(0, height - 1)
    model = depth[frame_index[:, None], rows, columns]
    valid = inside & (model > 0) & (joints_depth > 0) & torch.isfinite(model)
    ratios = torch.where(valid, joints_depth / model.clamp_min(1e-12),
                         torch.full_like(model, float('nan')))
    return ratios.nanmedian(dim=-1).values
