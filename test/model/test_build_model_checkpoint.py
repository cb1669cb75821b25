"""Tests of engine/model_builder.py with checkpoints: whole-model, or composed from parts."""

import logging

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.config import ModelSelection
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.settings import load_engine_config
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.model.infinihand_model import load_branch_configs
from infinihand_ros.model.io.bundled import bundled_models
from infinihand_ros.model.io.bundled import DEFAULT_MODEL
from infinihand_ros.model.io.bundled import resolve_checkpoint
from infinihand_ros.model.io.checkpoint import GEOMETRY_FILE
from infinihand_ros.model.io.checkpoint import HAND_BRANCH_FILE
from infinihand_ros.model.io.checkpoint import save_infinihand_checkpoint
from infinihand_ros.model.io.checkpoint import write_checkpoint
import pytest
import torch


def _engine(**model: object) -> EngineConfig:
    """Return the default engine config with ``engine.model`` fields (seeded: no checkpoint)."""
    return EngineConfig(model=ModelSelection(**{'checkpoint': None, **model}))


def _assert_same_weights(ours: InfiniHandModel, theirs: InfiniHandModel) -> None:
    expected = theirs.state_dict()
    assert ours.state_dict().keys() == expected.keys()
    for key, tensor in ours.state_dict().items():
        assert torch.equal(tensor, expected[key]), key


def test_shipped_engine_config_runs_the_bundled_model() -> None:
    selection = load_engine_config().model
    assert (selection.checkpoint, selection.geometry_weights,
            selection.crop_encoder_weights) == (DEFAULT_MODEL, None, None)
    assert DEFAULT_MODEL in bundled_models()


def test_bundled_names_and_directories_resolve(tmp_path) -> None:
    assert resolve_checkpoint(str(tmp_path)) == tmp_path
    assert resolve_checkpoint(DEFAULT_MODEL).name == DEFAULT_MODEL
    with pytest.raises(CheckpointError, match=f'bundled: .*{DEFAULT_MODEL}'):
        resolve_checkpoint('no_such_model')


def test_without_checkpoint_weights_are_seeded(hand_config: HandBranchConfig) -> None:
    built = build_model(_engine(seed=3))
    assert not built.training
    geometry_config, _ = load_branch_configs('tiny', 'tiny')
    _assert_same_weights(built, build_infinihand_model(geometry_config, hand_config, seed=3))


def test_checkpoint_weights_are_loaded_without_warning(model: InfiniHandModel, tmp_path,
                                                       caplog) -> None:
    directory = save_infinihand_checkpoint(model, tmp_path / 'ckpt')
    config = _engine(geometry=str(directory / GEOMETRY_FILE),
                     hand_branch=str(directory / HAND_BRANCH_FILE), checkpoint=str(directory),
                     seed=7)
    with caplog.at_level(logging.INFO):
        built = build_model(config)
    assert not built.training
    _assert_same_weights(built, model)
    assert not [record for record in caplog.records if record.levelno >= logging.WARNING]
    assert 'model loaded:' in caplog.text


def test_checkpoint_configs_win_with_a_warning(model: InfiniHandModel, tmp_path,
                                               caplog) -> None:
    directory = save_infinihand_checkpoint(model, tmp_path / 'ckpt')
    with caplog.at_level(logging.WARNING):
        built = build_model(_engine(checkpoint=str(directory)))  # tiny + tiny named
    assert built.geometry.config == model.geometry.config
    _assert_same_weights(built, model)
    messages = [record.getMessage() for record in caplog.records]
    assert len(messages) == 1
    assert 'geometry config differs from engine.model.geometry' in messages[0]
    assert str(directory) in messages[0]


def test_missing_checkpoint_fails_clearly(tmp_path) -> None:
    with pytest.raises(CheckpointError, match='absent.*no such directory and no bundled model'):
        build_model(_engine(checkpoint=str(tmp_path / 'absent')))


def test_weight_parts_compose_and_hand_models_are_passed(model: InfiniHandModel,
                                                         tmp_path) -> None:
    """geometry_weights and crop_encoder_weights load together, the rest seeded."""
    tensors = model.state_dict()
    geometry = write_checkpoint(tmp_path / 'geometry', {
        key: value for key, value in tensors.items()
        if key.startswith('geometry.') and not key.startswith('geometry.mask_head.')},
        geometry_config=model.geometry.config)
    crop = write_checkpoint(tmp_path / 'crop', {
        key: value for key, value in tensors.items()
        if key.startswith('hand_branch.backbone.')}, hand_config=model.hand_branch.config)
    hands = (BuiltinHandModel(LEFT), BuiltinHandModel(RIGHT))
    built = build_model(_engine(geometry_weights=str(geometry), crop_encoder_weights=str(crop),
                                seed=9), hand_models=hands)
    assert built.hand_branch.hand_models[0] is hands[0]
    seeded = build_infinihand_model(model.geometry.config, model.hand_branch.config,
                                    seed=9).state_dict()
    for key, tensor in built.state_dict().items():
        from_parts = key.startswith(('geometry.aggregator', 'geometry.camera_head',
                                     'geometry.depth_head', 'hand_branch.backbone'))
        if not key.startswith('geometry.mask_head.'):
            assert torch.equal(tensor, tensors[key] if from_parts else seeded[key]), key
