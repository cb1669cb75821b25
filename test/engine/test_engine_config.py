"""Tests of engine/config.py: one validated tree, devices, BA forms, resolved dumps."""

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.core.config import dump_config
from infinihand_ros.core.config import load_config
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.config import check_device
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.settings import load_engine_config
from infinihand_ros.model.infinihand_model import load_branch_configs
from infinihand_ros.model.io.bundled import resolve_checkpoint
from infinihand_ros.model.io.checkpoint import read_checkpoint
import pytest
import torch


def _write(tmp_path, text: str):
    path = tmp_path / 'engine.yaml'
    path.write_text(text, encoding='utf-8')
    return path


def test_the_package_config_loads() -> None:
    """config/engine.yaml is valid, has BA off and boxes the region around each mask peak."""
    config = load_engine_config()
    assert config.bundle_adjustment is None and config.model.geometry == 'tiny_336'
    assert config.detection.peak_region


def test_the_package_config_names_the_bundled_models_sizes() -> None:
    """The default model configs are the bundled checkpoint's own (no "checkpoint wins")."""
    config = load_engine_config()
    geometry, hand_branch = load_branch_configs(config.model.geometry, config.model.hand_branch)
    bundled = read_checkpoint(resolve_checkpoint(config.model.checkpoint))
    assert bundled.geometry_config == geometry and bundled.hand_config == hand_branch


@pytest.mark.parametrize('device, message', [
    ('foo', 'not a torch device'), ('meta', 'meta device holds no data'),
    ('cuda:99', 'CUDA')])
def test_bad_devices_name_the_key(device: str, message: str) -> None:
    """Unknown, meta and absent CUDA devices fail at load naming engine.device."""
    if device.startswith('cuda') and torch.cuda.device_count() > 99:
        pytest.skip('this machine has 100 GPUs')
    with pytest.raises(ConfigError, match=f'engine.device: .*{message}'):
        check_device(device)


@pytest.mark.skipif(torch.cuda.is_available(), reason='needs a machine without CUDA')
def test_cuda_on_a_cpu_machine_is_refused_at_load(tmp_path) -> None:
    """A YAML asking for cuda on a CPU-only machine gives the key, not torch's assertion."""
    with pytest.raises(ConfigError, match='engine.device.*no usable CUDA'):
        load_engine_config(_write(tmp_path, 'engine:\n  device: cuda\n'))


def test_bundle_adjustment_forms(tmp_path) -> None:
    """null/false: off; true: the package's ba.yaml; a path; inline settings."""
    assert load_engine_config(_write(tmp_path, 'engine:\n  bundle_adjustment: false\n')
                              ).bundle_adjustment is None
    packaged = load_engine_config(_write(tmp_path, 'engine:\n  bundle_adjustment: true\n'))
    assert isinstance(packaged.bundle_adjustment, BAConfig)
    inline = load_engine_config(_write(
        tmp_path, 'engine:\n  bundle_adjustment:\n    pool: {trigger: 8, stride: 2}\n'))
    assert inline.bundle_adjustment.pool.trigger == 8
    ba_file = tmp_path / 'ba.yaml'
    ba_file.write_text('ba:\n  pool: {trigger: 9}\n', encoding='utf-8')
    from_file = load_engine_config(_write(
        tmp_path, f'engine:\n  bundle_adjustment: {ba_file}\n'))
    assert from_file.bundle_adjustment.pool.trigger == 9


def test_bad_nested_values_name_their_key(tmp_path) -> None:
    """Errors deep in the tree name the dotted key."""
    with pytest.raises(ConfigError, match='klt_window_px'):
        load_engine_config(_write(
            tmp_path, 'engine:\n  bundle_adjustment:\n    tracking: {klt_window_px: 2}\n'))
    with pytest.raises(ConfigError, match='engine.model.*unknown key'):
        load_engine_config(_write(tmp_path, 'engine:\n  model: {geometri: tiny}\n'))
    with pytest.raises(ConfigError, match='hand_model.mano_dir'):
        load_engine_config(_write(
            tmp_path, 'engine:\n  model:\n    hand_model: {kind: mano, mano_dir: /nowhere}\n'))
    for bad in ('-1', '2.5', 'true'):
        with pytest.raises(ConfigError, match='engine.detection.region_join_px'):
            load_engine_config(_write(
                tmp_path, f'engine:\n  detection: {{region_join_px: {bad}}}\n'))


def test_geometry_lag_stays_below_the_geometry_interval(tmp_path) -> None:
    """A lag of n frames needs n < geometry_interval; bad values name the key."""
    assert load_engine_config(_write(
        tmp_path, 'engine: {geometry_interval: 3, geometry_lag: 2}\n')).geometry_lag == 2
    assert EngineConfig(geometry_interval=1, geometry_lag=4).geometry_lag == 4  # unused there
    with pytest.raises(ConfigError, match='geometry_lag .3. must be below'):
        EngineConfig(geometry_interval=3, geometry_lag=3)
    for bad in ('-1', '1.5', 'true'):
        with pytest.raises(ConfigError, match='engine.geometry_lag'):
            load_engine_config(_write(tmp_path, f'engine: {{geometry_lag: {bad}}}\n'))


def test_dump_config_round_trips_complete(tmp_path) -> None:
    """The resolved config dumps to YAML that loads back equal, even with require_complete."""
    config = EngineConfig(mode='windowed', window=4, bundle_adjustment=BAConfig())
    path = _write(tmp_path, dump_config(config, 'engine'))
    assert load_config(path, 'engine', EngineConfig, require_complete=True) == config
