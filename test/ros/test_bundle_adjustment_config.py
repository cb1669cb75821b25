"""The BA node's parameters and BA settings (ros/bundle_adjustment/config.py)."""

from pathlib import Path

from infinihand_ros.ba.config import load_ba_config
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.parameters import parameter_table
from infinihand_ros.ros.bundle_adjustment.config import ba_node_config_from_parameters
from infinihand_ros.ros.bundle_adjustment.config import BundleAdjustmentNodeConfig
import pytest


def _defaults() -> dict[str, object]:
    return {name: default
            for name, (default, _) in parameter_table(BundleAdjustmentNodeConfig).items()}


def test_the_parameter_defaults_build_the_default_config() -> None:
    """The tree's parameter defaults (the shipped file's) give the dataclass defaults."""
    config = ba_node_config_from_parameters(_defaults())
    assert config == BundleAdjustmentNodeConfig()
    assert config.ba_config() == load_ba_config()


def test_a_partial_ba_file_keeps_the_other_defaults(tmp_path: Path) -> None:
    """A partial BA YAML named by ``config``: its pool values, the rest defaults."""
    path = tmp_path / 'ba.yaml'
    path.write_text('ba:\n  pool:\n    trigger: 6\n')
    ba = BundleAdjustmentNodeConfig(config=str(path)).ba_config()
    assert (ba.pool.trigger, ba.pool.stride) == (6, load_ba_config().pool.stride)


@pytest.mark.parametrize('name,value,match', [
    ('config', '/no/such/ba.yaml', 'config'),
    ('keyframes.max_pending', 0, 'keyframes.max_pending'),
    ('keyframes.max_gap_s', 0.0, 'keyframes.max_gap_s'),
    ('world_frame_id', '', 'world_frame_id'),
    ('status_period_s', 'often', 'status_period_s'),
])
def test_bad_values_name_the_parameter(name: str, value: object, match: str) -> None:
    """A bad value raises ConfigError naming the parameter."""
    values = _defaults()
    values[name] = value
    with pytest.raises(ConfigError, match=match):
        ba_node_config_from_parameters(values).ba_config()
