"""The node's engine configuration (ros/estimator/engine_setup.py)."""

from pathlib import Path

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.config import load_engine_config
from infinihand_ros.ros.estimator.config import EngineSelection
from infinihand_ros.ros.estimator.engine_setup import engine_config_for
import pytest


def test_defaults_are_the_engine_file_with_the_node_settings() -> None:
    """Defaults give config/engine.yaml; mode, interval and BA follow the parameters."""
    assert engine_config_for(EngineSelection()) == load_engine_config()
    config = engine_config_for(EngineSelection(mode='windowed', keyframe_interval=3,
                                               bundle_adjustment='in_process'))
    assert (config.mode, config.keyframe_interval) == ('windowed', 3)
    assert config.bundle_adjustment is not None


def test_checkpoint_parameter_replaces_the_model_weights(tmp_path: Path) -> None:
    """An existing checkpoint directory becomes engine.model.checkpoint."""
    config = engine_config_for(EngineSelection(checkpoint=str(tmp_path)))
    assert config.model.checkpoint == str(tmp_path)


@pytest.mark.parametrize('selection,match', [
    (EngineSelection(checkpoint='/no/such/checkpoint'), 'engine.checkpoint'),
    (EngineSelection(config='/no/such/engine.yaml'), 'engine.config'),
    (EngineSelection(device='cuda:99'), 'engine.device'),
    (EngineSelection(device='tpu'), 'engine.device'),
])
def test_bad_engine_parameters_are_named(selection: EngineSelection, match: str) -> None:
    """Missing paths and unusable devices raise ConfigError naming the parameter."""
    with pytest.raises(ConfigError, match=match):
        engine_config_for(selection)


def test_node_bundle_adjustment_runs_no_ba_in_the_engine() -> None:
    """With the BA node the engine's own BA worker stays off."""
    config = engine_config_for(EngineSelection(bundle_adjustment='node'))
    assert config.bundle_adjustment is None
