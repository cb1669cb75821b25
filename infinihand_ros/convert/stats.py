"""Feature statistics in LeRobot's form: per episode, and merged over episodes.

Each feature gets min, max, mean, std, count and the quantiles q01, q10, q50, q90, q99, per
dimension. NaN values (an ``invalid_fill`` of NaN) are left out. Video statistics are per
channel in [0, 1], shaped (3, 1, 1) as LeRobot stores them, and exact: they come from
256-bin histograms of every frame. Merging weights means and quantiles by count and pools the
variances (quantiles of a merge are count-weighted means, as LeRobot merges them).
"""

from typing import Final
import warnings

import numpy as np

QUANTILES: Final = {'q01': 0.01, 'q10': 0.10, 'q50': 0.50, 'q90': 0.90, 'q99': 0.99}
STAT_NAMES: Final = ('min', 'max', 'mean', 'std', 'count', *QUANTILES)
LEVELS: Final = 256

Stats = dict[str, np.ndarray]


def vector_stats(values: np.ndarray) -> Stats:
    """Return the statistics of (N, D) values per dimension (NaN ignored; all-NaN gives NaN)."""
    data = np.asarray(values, dtype=np.float64).reshape(len(values), -1)
    with warnings.catch_warnings():  # an all-NaN dimension (a hand never seen) is expected
        warnings.simplefilter('ignore', RuntimeWarning)
        out: Stats = {'min': np.nanmin(data, axis=0), 'max': np.nanmax(data, axis=0),
                      'mean': np.nanmean(data, axis=0), 'std': np.nanstd(data, axis=0),
                      'count': np.array([len(data)], dtype=np.int64)}
        for name, q in QUANTILES.items():
            out[name] = np.nanquantile(data, q, axis=0)
    return out


class ImageStats:
    """Per-channel histograms of uint8 RGB frames, turned into LeRobot image statistics."""

    def __init__(self) -> None:
        """Start with no frame."""
        self._histograms = np.zeros((3, LEVELS), dtype=np.int64)
        self._frames = 0

    def add(self, rgb: np.ndarray) -> None:
        """Count the pixels of one (H, W, 3) uint8 frame."""
        for channel in range(3):
            self._histograms[channel] += np.bincount(rgb[:, :, channel].reshape(-1),
                                                     minlength=LEVELS)
        self._frames += 1

    def stats(self) -> Stats:
        """Return min, max, mean, std, quantiles (3, 1, 1) in [0, 1] and count [frames]."""
        levels = np.arange(LEVELS) / (LEVELS - 1)
        hist = self._histograms.astype(np.float64)
        total = hist.sum(axis=1)
        mean = hist @ levels / total
        std = np.sqrt(np.maximum(hist @ levels ** 2 / total - mean ** 2, 0.0))
        cumulative = np.cumsum(hist, axis=1) / total[:, None]
        present = hist > 0
        out: Stats = {
            'min': levels[present.argmax(axis=1)],
            'max': levels[LEVELS - 1 - present[:, ::-1].argmax(axis=1)],
            'mean': mean, 'std': std}
        for name, q in QUANTILES.items():
            out[name] = levels[(cumulative < q).sum(axis=1)]
        shaped = {name: value.reshape(3, 1, 1) for name, value in out.items()}
        shaped['count'] = np.array([self._frames], dtype=np.int64)
        return shaped


def merge_stats(parts: list[Stats]) -> Stats:
    """Merge the statistics of several episodes of one feature (weights are the counts)."""
    counts = np.array([float(part['count'][0]) for part in parts])
    weights = counts / counts.sum()

    def weighted(name: str) -> np.ndarray:
        return sum(w * np.asarray(part[name], dtype=np.float64)
                   for w, part in zip(weights, parts))

    mean = weighted('mean')
    second = sum(w * (np.asarray(part['std'], dtype=np.float64) ** 2
                      + (np.asarray(part['mean'], dtype=np.float64) - mean) ** 2)
                 for w, part in zip(weights, parts))
    out: Stats = {
        'min': np.min([part['min'] for part in parts], axis=0),
        'max': np.max([part['max'] for part in parts], axis=0),
        'mean': mean, 'std': np.sqrt(second),
        'count': np.array([int(counts.sum())], dtype=np.int64)}
    for name in QUANTILES:
        out[name] = weighted(name)
    return out
