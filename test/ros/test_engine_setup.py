"""The node's engine settings (ros/estimator/engine_setup.py)."""

from dataclasses import replace
from pathlib import Path

from infinihand_ros.ba.config import load_ba_config
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.output.config import SmoothingConfig
from infinihand_ros.engine.settings import build_engine_config
from infinihand_ros.ros.estimator.config import EngineSelection
from infinihand_ros.ros.estimator.config import EstimatorConfig
from infinihand_ros.ros.estimator.engine_setup import engine_config_for
import pytest


def _node(**selection: object) -> EstimatorConfig:
    """Return the node's default config with these ``engine.*`` parameters."""
    return EstimatorConfig(engine=EngineSelection(**selection))


def test_defaults_are_the_live_profile() -> None:
    """The node's defaults are the engine's (the live profile): MediaPipe hands, no BA."""
    node = engine_config_for(_node())
    assert node == EngineConfig() == build_engine_config('live')
    assert node.hands.source == 'mediapipe' and node.bundle_adjustment is None
    assert engine_config_for(_node(bundle_adjustment='in_process')).bundle_adjustment == \
        replace(load_ba_config(), worker=replace(load_ba_config().worker, when_behind='drop'))


def test_profile_and_set_reach_the_engine() -> None:
    """engine.profile names the profile; engine.set overrides it, last."""
    teleop = engine_config_for(_node(profile='teleop'))
    assert teleop.camera_motion == 'static'
    config = engine_config_for(_node(profile='offline', bundle_adjustment='none',
                                     set='geometry_interval=1 keyframe_interval=3'))
    assert (config.mode, config.keyframe_interval, config.geometry_interval) == \
        ('windowed', 3, 1)
    assert config.bundle_adjustment is None  # the node's none wins over the profile's BA
    assert engine_config_for(_node(set='restart_after_s=2.5')).restart_after_s == 2.5
    synthetic = engine_config_for(_node(profile='synthetic'))
    assert synthetic.hands.source == 'infinihand'  # hands.* left at its default: the profile's


def test_in_process_ba_never_makes_the_node_wait(tmp_path: Path) -> None:
    """A settings file whose BA waits for room (offline settings) still drops in the node."""
    engine_file = tmp_path / 'engine.yaml'
    engine_file.write_text('engine:\n  bundle_adjustment:\n    pool: {trigger: 8, stride: 2}\n'
                           '    worker: {when_behind: wait}\n')
    ba = engine_config_for(_node(config=str(engine_file),
                                 bundle_adjustment='in_process')).bundle_adjustment
    assert ba.worker.when_behind == 'drop'
    assert ba.pool.trigger == 8


def test_engine_section_parameters_reach_the_engine() -> None:
    """hands.* and smoothing.* are the engine's sections; a changed one wins over the profile."""
    smoothing = SmoothingConfig(mode='one_euro', beta=0.5)
    config = engine_config_for(EstimatorConfig(
        engine=EngineSelection(profile='synthetic'), smoothing=smoothing,
        hands=HandsConfig(source='mediapipe', min_confidence=0.7)))
    assert config.output.smoothing == smoothing
    assert config.hands.min_confidence == 0.7
    # source left at its default: the synthetic profile's infinihand stands
    assert config.hands.source == 'infinihand'


def test_checkpoint_parameter_replaces_the_model_weights(tmp_path: Path) -> None:
    """An existing checkpoint directory becomes engine.model.checkpoint."""
    config = engine_config_for(_node(checkpoint=str(tmp_path)))
    assert config.model.checkpoint == str(tmp_path)


@pytest.mark.parametrize('selection,match', [
    ({'checkpoint': '/no/such/checkpoint'}, 'engine.checkpoint'),
    ({'config': '/no/such/engine.yaml'}, 'engine.config'),
    ({'set': 'device=cuda:99'}, 'engine.device'),
    ({'set': 'device=tpu'}, 'engine.device'),
    ({'set': 'geometry_interval'}, 'engine.set'),
    ({'set': 'no_such_setting=1'}, 'no_such_setting'),
    ({'profile': 'lab'}, 'engine.profile'),
])
def test_bad_engine_parameters_are_named(selection: dict, match: str) -> None:
    """Missing paths, unusable devices and bad overrides raise ConfigError naming them."""
    with pytest.raises(ConfigError, match=match):
        engine_config_for(_node(**selection))


def test_node_bundle_adjustment_runs_no_ba_in_the_engine() -> None:
    """With the BA node the engine's own BA worker stays off."""
    config = engine_config_for(_node(bundle_adjustment='node'))
    assert config.bundle_adjustment is None
