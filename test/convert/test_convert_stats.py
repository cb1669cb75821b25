"""Tests of infinihand_ros/convert/stats.py: vector and image statistics, merging."""

from infinihand_ros.convert.stats import ImageStats
from infinihand_ros.convert.stats import merge_stats
from infinihand_ros.convert.stats import vector_stats
import numpy as np


def test_vector_stats_ignore_nan(rng: np.random.Generator) -> None:
    """Per-dimension statistics equal numpy's; NaN entries are left out."""
    values = rng.normal(size=(50, 3))
    values[::5, 1] = np.nan
    stats = vector_stats(values)
    np.testing.assert_allclose(stats['mean'], np.nanmean(values, axis=0))
    np.testing.assert_allclose(stats['q50'], np.nanmedian(values, axis=0))
    assert stats['count'].tolist() == [50]
    assert np.isnan(vector_stats(np.full((4, 1), np.nan))['mean'][0])


def test_image_stats_are_exact(rng: np.random.Generator) -> None:
    """Histogram statistics match the pixels' own, per channel, in [0, 1], shaped (3, 1, 1)."""
    frames = [rng.integers(0, 256, (8, 10, 3), dtype=np.uint8) for _ in range(3)]
    accumulator = ImageStats()
    for frame in frames:
        accumulator.add(frame)
    stats = accumulator.stats()
    pixels = np.stack(frames).reshape(-1, 3) / 255.0
    assert stats['mean'].shape == (3, 1, 1)
    np.testing.assert_allclose(stats['mean'].reshape(3), pixels.mean(axis=0))
    np.testing.assert_allclose(stats['std'].reshape(3), pixels.std(axis=0))
    np.testing.assert_allclose(stats['max'].reshape(3), pixels.max(axis=0))
    np.testing.assert_allclose(stats['min'].reshape(3), pixels.min(axis=0))
    assert stats['count'].tolist() == [3]


def test_merge_equals_stats_of_the_union(rng: np.random.Generator) -> None:
    """Merged mean, std, min and max equal those of the concatenated episodes."""
    first, second = rng.normal(size=(20, 2)), rng.normal(3.0, 2.0, size=(60, 2))
    merged = merge_stats([vector_stats(first), vector_stats(second)])
    union = np.concatenate([first, second])
    np.testing.assert_allclose(merged['mean'], union.mean(axis=0))
    np.testing.assert_allclose(merged['std'], union.std(axis=0))
    np.testing.assert_allclose(merged['min'], union.min(axis=0))
    assert merged['count'].tolist() == [80]
