"""The node's engine configuration (ros/estimator/engine_setup.py)."""

from dataclasses import replace
from pathlib import Path

from infinihand_ros.ba.config import load_ba_config
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.config import load_engine_config
from infinihand_ros.engine.output.config import SmoothingConfig
from infinihand_ros.ros.estimator.config import CameraSettings
from infinihand_ros.ros.estimator.config import EngineSelection
from infinihand_ros.ros.estimator.config import EstimatorConfig
from infinihand_ros.ros.estimator.engine_setup import engine_config_for
import pytest


def _node(**selection: object) -> EstimatorConfig:
    """Return the node's default config with these ``engine.*`` parameters."""
    return EstimatorConfig(engine=EngineSelection(**selection))


def test_defaults_are_the_engine_file_with_the_node_settings() -> None:
    """Defaults: config/engine.yaml with MediaPipe hands, no BA, geometry two frames late.

    (The engine file takes a frame's owed geometry in before the next frame.) in_process BA:
    config/ba.yaml.
    """
    node = engine_config_for(_node())
    assert node.hands.source == 'mediapipe' and load_engine_config().hands.source == 'infinihand'
    assert load_engine_config().bundle_adjustment is None and node.bundle_adjustment is None
    assert (node.geometry_lag, load_engine_config().geometry_lag) == (2, 0)
    assert node == replace(load_engine_config(), hands=node.hands, geometry_lag=2)
    assert engine_config_for(_node(bundle_adjustment='in_process')).bundle_adjustment == \
        load_ba_config()
    config = engine_config_for(_node(mode='windowed', keyframe_interval=3, geometry_interval=1,
                                     bundle_adjustment='none'))
    assert (config.mode, config.keyframe_interval, config.geometry_interval) == ('windowed', 3, 1)
    assert config.bundle_adjustment is None


def test_in_process_ba_never_makes_the_node_wait(tmp_path: Path) -> None:
    """An engine file whose BA waits for room (offline settings) still drops in the node."""
    engine_file = tmp_path / 'engine.yaml'
    engine_file.write_text('engine:\n  bundle_adjustment:\n    pool: {trigger: 8, stride: 2}\n'
                           '    worker: {when_behind: wait}\n')
    assert load_engine_config(engine_file).bundle_adjustment.worker.when_behind == 'wait'
    ba = engine_config_for(_node(config=str(engine_file),
                                 bundle_adjustment='in_process')).bundle_adjustment
    assert ba.worker.when_behind == 'drop'
    assert ba.pool.trigger == 8


def test_camera_motion_and_output_parameters_reach_the_engine() -> None:
    """camera.* are the engine's camera_motion and restart_after_s; smoothing.* its output's."""
    smoothing = SmoothingConfig(mode='one_euro', beta=0.5)
    config = engine_config_for(EstimatorConfig(
        camera=CameraSettings(motion='static', restart_after_s=2.5), smoothing=smoothing))
    assert config.camera_motion == 'static' and config.restart_after_s == 2.5
    assert config.output.smoothing == smoothing
    assert engine_config_for(_node()).restart_after_s == CameraSettings().restart_after_s


def test_checkpoint_parameter_replaces_the_model_weights(tmp_path: Path) -> None:
    """An existing checkpoint directory becomes engine.model.checkpoint."""
    config = engine_config_for(_node(checkpoint=str(tmp_path)))
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
        engine_config_for(EstimatorConfig(engine=selection))


def test_node_bundle_adjustment_runs_no_ba_in_the_engine() -> None:
    """With the BA node the engine's own BA worker stays off."""
    config = engine_config_for(_node(bundle_adjustment='node'))
    assert config.bundle_adjustment is None
