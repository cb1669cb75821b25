"""Tests of model/config.py: the shipped YAML files and rejected values."""

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.model.config import AggregatorConfig
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.config import MemoryConfig
from infinihand_ros.model.config import named_config_path
import pytest


@pytest.mark.parametrize('name', ['paper', 'tiny'])
def test_shipped_configs_load(name: str) -> None:
    """Both shipped configurations load and have consistent patch grids."""
    config = load_geometry_config(named_config_path(name))
    height, width = config.aggregator.patch_grid
    assert height * config.aggregator.patch_size == config.aggregator.image_height
    assert width * config.aggregator.patch_size == config.aggregator.image_width
    assert config.aggregator.num_special_tokens == 6


def test_paper_config_uses_lingbot_map_sizes() -> None:
    """The paper configuration has LingBot-Map's input, widths, memory and conventions."""
    config = load_geometry_config(named_config_path('paper'), require_complete=True)
    assert (config.aggregator.image_width, config.aggregator.image_height) == (518, 378)
    assert (config.aggregator.embed_dim, config.aggregator.depth) == (1024, 24)
    assert (config.memory.anchor_frames, config.memory.window) == (8, 64)
    assert (config.pose_direction, config.preprocessing) == ('cam_to_world', 'resize_crop')


def test_tiny_config_keeps_our_conventions() -> None:
    """The tiny configuration letterboxes and decodes camera-to-world, like the defaults."""
    config = load_geometry_config(named_config_path('tiny'))
    assert (config.pose_direction, config.preprocessing) == ('cam_to_world', 'letterbox')
    assert (GeometryConfig().pose_direction, GeometryConfig().preprocessing) == (
        'cam_to_world', 'letterbox')


@pytest.mark.parametrize('line, message', [
    ('pose_direction: c2w', "pose_direction must be one of .*got 'c2w'"),
    ('preprocessing: crop', "preprocessing must be one of .*got 'crop'"),
])
def test_bad_conventions_are_config_errors(tmp_path, line: str, message: str) -> None:
    """An unknown pose direction or preprocessing mode in the YAML names the value."""
    path = tmp_path / 'model.yaml'
    path.write_text(f'geometry:\n  {line}\n')
    with pytest.raises(ConfigError, match=message):
        load_geometry_config(path)


def test_incomplete_yaml_is_refused_when_completeness_is_required(tmp_path) -> None:
    """require_complete names the missing field instead of filling in its default."""
    path = tmp_path / 'model.yaml'
    path.write_text(named_config_path('tiny').read_text().replace(
        '  preprocessing: letterbox', '  # preprocessing left out'))
    assert load_geometry_config(path).preprocessing == 'letterbox'
    with pytest.raises(ConfigError, match='preprocessing'):
        load_geometry_config(path, require_complete=True)


@pytest.mark.parametrize('kwargs, message', [
    ({'image_height': 50}, 'multiple of patch_size'),
    ({'rope3d_split': (20, 20, 20)}, 'rope3d_split'),
    ({'selected_layers': (0, 1, 2, 9)}, 'selected_layers'),
    ({'global_rope': 'learned'}, 'global_rope'),
])
def test_bad_aggregator_values_are_rejected(kwargs: dict, message: str) -> None:
    """Inconsistent aggregator sizes raise ValueError naming the field."""
    with pytest.raises(ValueError, match=message):
        AggregatorConfig(**kwargs)


def test_negative_window_is_rejected() -> None:
    """A negative window is refused."""
    with pytest.raises(ValueError, match='memory.window'):
        MemoryConfig(window=-1)


def test_unknown_yaml_key_is_a_config_error(tmp_path) -> None:
    """Unknown keys in the YAML raise ConfigError naming the key."""
    path = tmp_path / 'model.yaml'
    path.write_text('geometry:\n  memory:\n    anchors: 3\n')
    with pytest.raises(ConfigError, match='anchors'):
        load_geometry_config(path)
