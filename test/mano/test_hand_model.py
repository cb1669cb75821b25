"""Tests of the hand-model configuration, factory and canonical joints."""

from pathlib import Path
import shutil

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.engine.settings import load_engine_config
from infinihand_ros.mano import builtin
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.mano.hand_model import build_hand_model
from infinihand_ros.mano.hand_model import canonical_joints
from infinihand_ros.mano.hand_model import HandModel
from infinihand_ros.mano.hand_model import HandModelConfig
from infinihand_ros.mano.hand_model import load_hand_model_config
from infinihand_ros.mano.mano_file import load_mano_data
from infinihand_ros.mano.mano_layer import ManoHandModel
from infinihand_ros.mano.mirror import mirror_points
import numpy as np
import pytest
import torch


def test_repository_config_selects_the_builtin_model() -> None:
    config = load_engine_config().model.hand_model
    assert config == HandModelConfig(kind='builtin', mano_dir='')
    model = build_hand_model(config, LEFT)
    assert isinstance(model, BuiltinHandModel) and isinstance(model, HandModel)
    assert model.side == LEFT


def test_config_rejects_unknown_kinds_types_and_a_missing_mano_dir(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"unknown kind 'smplx'; use one of \['builtin', 'mano'"):
        HandModelConfig(kind='smplx')
    with pytest.raises(ConfigError, match='mano_dir: expected a string, got int 3'):
        HandModelConfig(mano_dir=3)
    with pytest.raises(ConfigError, match=r'download MANO at https://mano\.is\.tue\.mpg\.de, '
                                          r'then set mano_dir'):
        HandModelConfig(kind='mano')
    with pytest.raises(ConfigError, match='not an existing folder'):
        HandModelConfig(kind='mano', mano_dir=str(tmp_path / 'nowhere'))


@pytest.mark.parametrize(('text', 'message'), [
    ('hand_model: {kind: builtin, mano_path: x}', r"unknown key\(s\) \['mano_path'\]"),
    ('hand_model: {kind: 1}', 'hand_model.kind: expected str, got 1'),
    ('kind: builtin', "no top-level section 'hand_model'"),
    ('hand_model: [builtin]', 'expected a mapping of HandModelConfig fields'),
    ('hand_model: {kind: [', 'not valid YAML'),
])
def test_yaml_loader_rejects_bad_files(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / 'hand_model.yaml'
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_hand_model_config(path)
    with pytest.raises(ConfigError, match='cannot read'):
        load_hand_model_config(tmp_path / 'missing.yaml')


def test_mano_kind_builds_skinned_models_and_fixes_the_left_shapedirs(fake_mano_dir: Path) -> None:
    config = HandModelConfig(kind='mano', mano_dir=str(fake_mano_dir))
    right, left = build_hand_model(config, RIGHT), build_hand_model(config, LEFT)
    assert isinstance(right, ManoHandModel) and isinstance(left, ManoHandModel)
    assert (right.side, left.side) == (RIGHT, LEFT)
    # The fake left file repeats the right shapedirs (the official bug): x must come out negated.
    torch.testing.assert_close(left.shapedirs[:, 0], -right.shapedirs[:, 0])
    out = left(torch.zeros(2, 3), torch.zeros(2, 15, 3), torch.zeros(2, 10), torch.zeros(2, 3))
    assert out.vertices.shape == (2, 778, 3) and out.joints.shape == (2, NUM_JOINTS, 3)


def test_left_model_alone_loads_without_the_fix(tmp_path: Path, fake_mano_dir: Path) -> None:
    shutil.copy(fake_mano_dir / 'MANO_LEFT.pkl', tmp_path / 'MANO_LEFT.pkl')
    config = HandModelConfig(kind='mano', mano_dir=str(tmp_path))
    left = build_hand_model(config, LEFT)
    raw = load_mano_data(tmp_path / 'MANO_LEFT.pkl').shapedirs
    np.testing.assert_allclose(left.shapedirs.numpy(), raw, rtol=1e-6)
    with pytest.raises(CheckpointError, match=r'MANO_RIGHT\.pkl: MANO file not found; download'):
        build_hand_model(config, RIGHT)


def test_canonical_joints_are_the_root_relative_mean_hand() -> None:
    assert canonical_joints is builtin.canonical_joints  # re-exported for the metrics
    right, left = canonical_joints(RIGHT), canonical_joints(LEFT)
    assert right.shape == (NUM_JOINTS, 3) and right.dtype == np.float64
    np.testing.assert_array_equal(right[0], 0.0)
    np.testing.assert_allclose(left, mirror_points(right), atol=1e-12)
    model = BuiltinHandModel(RIGHT, dtype=torch.float64)
    out = model(torch.zeros(1, 3), torch.zeros(1, 15, 3), torch.zeros(1, 10), torch.ones(1, 3))
    np.testing.assert_allclose(out.joints[0].numpy() - 1.0, right, atol=1e-12)
    with pytest.raises(ValueError, match='hand side must be 0'):
        canonical_joints(5)
