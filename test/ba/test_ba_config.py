"""BA settings: the package's ba.yaml loads, values that make every BA call fail are refused."""

from pathlib import Path

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import load_ba_config
from infinihand_ros.core.errors import ConfigError
import pytest


def test_package_settings_load() -> None:
    assert isinstance(load_ba_config(), BAConfig)


@pytest.mark.parametrize(('section', 'key', 'value', 'message'), [
    ('tracking', 'klt_window_px', '2', 'ba.tracking.klt_window_px: must be >= 3, got 2'),
    ('tracking', 'corner_quality', '1.5', r'ba.tracking.corner_quality: must be in \(0, 1\)'),
    ('tracking', 'corner_quality', '1.0', r'ba.tracking.corner_quality: must be in \(0, 1\)'),
    ('tracking', 'corner_quality', '0', r'ba.tracking.corner_quality: must be in \(0, 1\)'),
    ('tracking', 'corner_quality', '.nan', 'ba.tracking.corner_quality: must be a finite'),
    ('tracking', 'max_depth_m', '.inf', 'ba.tracking.max_depth_m: must be a finite'),
    ('tracking', 'max_depth_m', '0.01', 'ba.tracking.max_depth_m: must be above min_depth_m'),
    ('tracking', 'fb_threshold_px', '0', 'ba.tracking.fb_threshold_px: must be positive'),
    ('tracking', 'ransac_threshold_px', '-1', 'ba.tracking.ransac_threshold_px: must be pos'),
    ('tracking', 'min_corner_distance_px', '-1', 'ba.tracking.min_corner_distance_px: must be'),
    ('tracking', 'hand_margin_px', '-1', 'ba.tracking.hand_margin_px: must be >= 0'),
    ('tracking', 'orb_max_hamming', '300', 'ba.tracking.orb_max_hamming: must be <= 256'),
    ('tracking', 'max_corners', '0', 'ba.tracking.max_corners: must be >= 8, got 0'),
    ('solver', 'huber_px', '.nan', 'ba.solver.huber_px: must be a finite number, got nan'),
    ('solver', 'rel_pose_sigma_m', '.inf', 'ba.solver.rel_pose_sigma_m: must be a finite'),
    ('solver', 'max_iterations', '0', 'ba.solver.max_iterations: must be >= 1, got 0'),
    ('solver', 'gate_px', '0', 'ba.solver.gate_px: must be positive, got 0.0'),
    ('pool', 'stride', '1', 'ba.pool.stride: must be >= 2, got 1'),
    ('pool', 'trigger', '0', 'ba.pool.trigger: must be >= 1, got 0'),
    ('corrections', 'blend_s', '.nan', 'ba.corrections.blend_s: must be a finite'),
    ('corrections', 'blend_s', '-0.1', 'ba.corrections.blend_s: must be >= 0, got -0.1'),
    ('worker', 'niceness', '20', r'ba.worker.niceness: must be in 0..19, got 20'),
    ('worker', 'max_queued_selections', '0', 'ba.worker.max_queued_selections: must be >= 1'),
    ('worker', 'when_behind', 'block', 'ba.worker.when_behind: must be one of drop, wait'),
])
def test_values_that_break_every_call_are_refused_at_load(tmp_path: Path, section: str,
                                                          key: str, value: str,
                                                          message: str) -> None:
    path = tmp_path / 'ba.yaml'
    path.write_text(f'ba:\n  {section}:\n    {key}: {value}\n')
    with pytest.raises(ConfigError, match=message) as error:
        load_ba_config(path)
    assert str(path) in str(error.value)
