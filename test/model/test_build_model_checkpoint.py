"""Tests of engine/model_builder.py with the engine.checkpoint option."""

import logging

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.config import load_engine_config
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.infinihand_checkpoint import GEOMETRY_FILE
from infinihand_ros.model.infinihand_checkpoint import HAND_BRANCH_FILE
from infinihand_ros.model.infinihand_checkpoint import save_infinihand_checkpoint
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.model.infinihand_model import load_branch_configs
import pytest
import torch


def _assert_same_weights(ours: InfiniHandModel, theirs: InfiniHandModel) -> None:
    expected = theirs.state_dict()
    assert ours.state_dict().keys() == expected.keys()
    for key, tensor in ours.state_dict().items():
        assert torch.equal(tensor, expected[key]), key


def test_shipped_engine_config_has_no_checkpoint() -> None:
    assert load_engine_config().checkpoint is None


def test_without_checkpoint_weights_are_seeded(hand_config: HandBranchConfig) -> None:
    config = EngineConfig(seed=3)
    built = build_model(config)
    assert not built.training
    geometry_config, _ = load_branch_configs('tiny', 'tiny')
    _assert_same_weights(built, build_infinihand_model(geometry_config, hand_config, seed=3))


def test_checkpoint_weights_are_loaded_without_warning(model: InfiniHandModel, tmp_path,
                                                       caplog) -> None:
    directory = save_infinihand_checkpoint(model, tmp_path / 'ckpt')
    config = EngineConfig(geometry=str(directory / GEOMETRY_FILE),
                          hand_branch=str(directory / HAND_BRANCH_FILE),
                          checkpoint=str(directory), seed=7)
    with caplog.at_level(logging.WARNING):
        built = build_model(config)
    assert not built.training
    _assert_same_weights(built, model)
    assert not caplog.records


def test_checkpoint_configs_win_with_a_warning(model: InfiniHandModel, tmp_path,
                                               caplog) -> None:
    directory = save_infinihand_checkpoint(model, tmp_path / 'ckpt')
    with caplog.at_level(logging.WARNING):
        built = build_model(EngineConfig(checkpoint=str(directory)))  # tiny + tiny named
    assert built.geometry.config == model.geometry.config
    _assert_same_weights(built, model)
    messages = [record.getMessage() for record in caplog.records]
    assert len(messages) == 1
    assert 'geometry config differs from engine.geometry' in messages[0]
    assert str(directory) in messages[0]


def test_missing_checkpoint_fails_clearly(tmp_path) -> None:
    with pytest.raises(CheckpointError, match='no such checkpoint directory'):
        build_model(EngineConfig(checkpoint=str(tmp_path / 'absent')))
