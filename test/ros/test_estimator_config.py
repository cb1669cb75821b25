"""The estimator's parameter tree, defaults file and specs (ros/estimator/config.py)."""

import dataclasses
from pathlib import Path

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.ros.estimator.config import estimator_config_from_parameters
from infinihand_ros.ros.estimator.config import EstimatorConfig
from infinihand_ros.ros.estimator.config import flatten
from infinihand_ros.ros.estimator.config import load_estimator_defaults
from infinihand_ros.ros.estimator.config import load_node_defaults
from infinihand_ros.ros.estimator.config import unflatten
from infinihand_ros.ros.estimator.parameter_specs import PARAMETER_SPECS
import pytest


def _field_names(cls: type, prefix: str = '') -> set[str]:
    names = set()
    for field in dataclasses.fields(cls):
        if dataclasses.is_dataclass(field.default_factory if field.default_factory
                                    is not dataclasses.MISSING else None):
            names |= _field_names(field.default_factory, f'{prefix}{field.name}.')
        else:
            names.add(f'{prefix}{field.name}')
    return names


def test_defaults_file_specs_and_dataclass_agree() -> None:
    """config/estimator.yaml, PARAMETER_SPECS and EstimatorConfig name the same parameters."""
    defaults = load_estimator_defaults()
    assert set(defaults) == set(PARAMETER_SPECS) == _field_names(EstimatorConfig)
    assert estimator_config_from_parameters(defaults) == EstimatorConfig()


def test_numeric_defaults_lie_in_their_ranges() -> None:
    """Every numeric default is within its declared range."""
    for name, value in load_estimator_defaults().items():
        spec = PARAMETER_SPECS[name]
        if spec.low is not None:
            assert spec.low <= value <= spec.high, name


def test_flatten_and_unflatten_are_inverse() -> None:
    """Dotted names round-trip."""
    tree = {'a': {'b': 1, 'c': {'d': 'x'}}, 'e': 2.0}
    assert flatten(tree) == {'a.b': 1, 'a.c.d': 'x', 'e': 2.0}
    assert unflatten(flatten(tree)) == tree


@pytest.mark.parametrize('name,value,match', [
    ('smoothing.mode', 'kalman', 'smoothing.mode'),
    ('camera.motion', 'moving', 'camera.motion'),
    ('engine.mode', 'batch', 'engine.mode'),
    ('engine.bundle_adjustment', 'remote', 'engine.bundle_adjustment'),
    ('ba_node.timeout_s', 0.0, 'ba_node.timeout_s'),
    ('camera.fallback.fx', 500.0, 'camera.fallback'),
    ('smoothing.min_cutoff_hz', 0.0, 'smoothing.min_cutoff_hz'),
    ('shape.min_confidence', 1.5, 'shape.min_confidence'),
    ('frames.world_frame_id', '', 'frames.world_frame_id'),
    ('outputs.path_length', 'long', 'outputs.path_length'),
    ('no.such', 1, 'no'),
])
def test_bad_values_name_the_parameter(name: str, value: object, match: str) -> None:
    """A wrong value or type raises ConfigError naming the parameter."""
    values = load_estimator_defaults()
    values[name] = value
    with pytest.raises(ConfigError, match=match):
        estimator_config_from_parameters(values)


@pytest.mark.parametrize('key', ['my_node', '/my_node', '/**'])
def test_params_file_section_by_name_or_wildcard(tmp_path: Path, key: str) -> None:
    """The node's own section, its slash form or the /** wildcard give the values."""
    path = tmp_path / 'params.yaml'
    path.write_text(f"'{key}':\n  ros__parameters:\n    camera:\n      motion: static\n")
    assert load_node_defaults(path, 'my_node') == {'camera.motion': 'static'}


def test_params_file_without_the_node_section_is_refused(tmp_path: Path) -> None:
    """Another node's section only: an error naming the file and the missing section."""
    path = tmp_path / 'params.yaml'
    path.write_text('other_node:\n  ros__parameters:\n    a: 1\n')
    with pytest.raises(ConfigError, match=r'params.yaml: no my_node.ros__parameters'):
        load_node_defaults(path, 'my_node')
