"""The estimator's parameter tree and its generated params file (ros/estimator/config.py)."""

import ast
from pathlib import Path

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.parameters import parameter_table
from infinihand_ros.core.parameters import unflatten
from infinihand_ros.ros.estimator.config import BA_MODES
from infinihand_ros.ros.estimator.config import estimator_config_from_parameters
from infinihand_ros.ros.estimator.config import EstimatorConfig
from infinihand_ros.tools import params_files
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
CONFIG_DIR = ROOT / 'config'


def _defaults() -> dict[str, object]:
    return {name: default for name, (default, _) in parameter_table(EstimatorConfig).items()}


def test_shipped_params_files_are_generated_from_the_dataclasses() -> None:
    """config/estimator.yaml and config/bundle_adjustment.yaml: exactly what the trees give."""
    for name, text in params_files.expected_files().items():
        assert (CONFIG_DIR / name).read_text() == text, (
            f'config/{name} drifted from its dataclass; run python -m '
            'infinihand_ros.tools.params_files --write')
    assert params_files.main(['--config-dir', str(CONFIG_DIR)]) == 0


def test_the_params_file_reads_back_to_the_defaults() -> None:
    """The generated file, read as ROS reads it, builds the default config."""
    data = yaml.safe_load((CONFIG_DIR / 'estimator.yaml').read_text())
    assert data['/**']['ros__parameters'] == unflatten(_defaults())
    assert estimator_config_from_parameters(_defaults()) == EstimatorConfig()


def test_every_parameter_is_described_and_numbers_lie_in_their_ranges() -> None:
    """Descriptions are sentences; numeric defaults within range; choices include the default."""
    for name, (default, spec) in parameter_table(EstimatorConfig).items():
        assert spec.description.endswith('.'), name
        if spec.low is not None:
            assert spec.low <= default <= spec.high, name
        if spec.choices:
            assert default in spec.choices, name
            assert all(choice in spec.full_description for choice in spec.choices), name
    bundle_adjustment = parameter_table(EstimatorConfig)['engine.bundle_adjustment'][1]
    assert 'off' not in bundle_adjustment.full_description


def test_the_launch_file_offers_the_node_ba_modes() -> None:
    """launch/estimator.launch.py passes only values engine.bundle_adjustment accepts."""
    tree = ast.parse((ROOT / 'launch' / 'estimator.launch.py').read_text())
    choices = [ast.literal_eval(statement.value) for statement in tree.body
               if isinstance(statement, ast.Assign)
               and [target.id for target in statement.targets] == ['BA_CHOICES']]
    assert len(choices) == 1 and sorted(choices[0]) == sorted(BA_MODES)


def test_unflatten_nests_dotted_names() -> None:
    """Dotted names become nested mappings."""
    nested = {'a': {'b': 1, 'c': {'d': 'x'}}, 'e': 2.0}
    assert unflatten({'a.b': 1, 'a.c.d': 'x', 'e': 2.0}) == nested


@pytest.mark.parametrize('name,value,match', [
    ('smoothing.mode', 'kalman', 'smoothing.mode'),
    ('engine.profile', 'lab', 'engine.profile'),
    ('engine.set', 'geometry_interval', 'engine.set'),
    ('engine.bundle_adjustment', 'remote', 'engine.bundle_adjustment'),
    ('ba_node.timeout_s', 0.0, 'ba_node.timeout_s'),
    ('camera.fallback.fx', 500.0, 'camera.fallback'),
    ('smoothing.min_cutoff_hz', 0.0, 'smoothing.min_cutoff_hz'),
    ('shape.min_confidence', 1.5, 'shape.min_confidence'),
    ('frames.world_frame_id', '', 'frames.world_frame_id'),
    ('frames.right_wrist_frame_id', '', 'frames.right_wrist_frame_id'),
    ('frames.left_wrist_frame_id', 'world', 'frame ids must differ'),
    ('tf.enabled', 'yes', 'tf.enabled'),
    ('outputs.path_length', 'long', 'outputs.path_length'),
    ('no.such', 1, 'no'),
])
def test_bad_values_name_the_parameter(name: str, value: object, match: str) -> None:
    """A wrong value or type raises ConfigError naming the parameter."""
    values = _defaults()
    values[name] = value
    with pytest.raises(ConfigError, match=match):
        estimator_config_from_parameters(values)
