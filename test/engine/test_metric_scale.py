"""The running metric-scale estimate recovers a known scale and ignores outliers."""

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.metric_scale import MetricScaleConfig
from infinihand_ros.engine.metric_scale import MetricScaleEstimator
import numpy as np
import pytest


def test_known_scale_is_recovered_despite_outliers(rng: np.random.Generator) -> None:
    true_scale = 0.37  # metres per model unit
    estimator = MetricScaleEstimator(MetricScaleConfig(history=200, min_samples=5))
    model = rng.uniform(1.0, 3.0, size=200)
    metric = true_scale * model * rng.normal(1.0, 0.02, size=200)
    metric[::10] *= 5.0  # 10 % gross outliers (wrong hand depth)
    model[3] = np.nan
    assert estimator.observe(metric, model) == 199
    estimate = estimator.estimate()
    assert estimate.scale == pytest.approx(true_scale, rel=0.02)
    assert 0 < estimate.uncertainty < 0.01
    assert estimate.samples == 199


def test_initial_scale_until_enough_samples_and_reset() -> None:
    estimator = MetricScaleEstimator(MetricScaleConfig(min_samples=3))
    estimator.observe(np.array([1.0, 2.0]), np.array([2.0, 4.0]))
    assert estimator.estimate().scale == 1.0 and estimator.estimate().uncertainty == np.inf
    estimator.observe(np.array([3.0]), np.array([6.0]))
    assert estimator.estimate().scale == pytest.approx(0.5)
    estimator.reset()
    assert estimator.estimate().samples == 0


def test_history_forgets_old_ratios() -> None:
    estimator = MetricScaleEstimator(MetricScaleConfig(history=10, min_samples=1))
    estimator.observe(np.full(10, 2.0), np.ones(10))
    estimator.observe(np.full(10, 3.0), np.ones(10))
    assert estimator.estimate().scale == pytest.approx(3.0)


def test_bad_settings_and_inputs() -> None:
    with pytest.raises(ConfigError, match='history >= min_samples'):
        MetricScaleConfig(history=2, min_samples=5)
    for correction in (0.0, -1.0, float('nan'), float('inf')):
        with pytest.raises(ConfigError, match='hand_depth_correction'):
            MetricScaleConfig(hand_depth_correction=correction)
    with pytest.raises(ValueError, match='same length'):
        MetricScaleEstimator().observe(np.ones(2), np.ones(3))
