"""Tests of model/checkpoint.py: safetensors round trip and checked loading."""

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.core.errors import InputError
from infinihand_ros.model.checkpoint import load_checkpoint
from infinihand_ros.model.checkpoint import load_state_dict_checked
from infinihand_ros.model.checkpoint import save_checkpoint
from infinihand_ros.model.geometry_model import GeometryModel
import pytest
import torch
from torch import nn


def test_save_and_load_round_trip(micro_model: GeometryModel, tmp_path) -> None:
    """A saved checkpoint reloads with the same config and identical tensors."""
    directory = save_checkpoint(micro_model, tmp_path / 'ckpt')
    assert sorted(path.name for path in directory.iterdir()) == ['config.yaml',
                                                                 'model.safetensors']
    loaded = load_checkpoint(directory)
    assert loaded.config == micro_model.config
    for key, tensor in micro_model.state_dict().items():
        assert torch.equal(loaded.state_dict()[key], tensor), key
    with pytest.raises(InputError, match='already exists'):
        save_checkpoint(micro_model, directory)


def test_checked_load_reports_every_difference() -> None:
    """Missing, unexpected and mismatched keys are all named and nothing is loaded."""
    module = nn.Sequential(nn.Linear(2, 3), nn.Linear(3, 1))
    before = module[0].weight.clone()
    state = {'0.weight': torch.ones(3, 2), '0.bias': torch.ones(4), 'extra': torch.ones(1)}
    with pytest.raises(CheckpointError) as info:
        load_state_dict_checked(module, state, 'test.ckpt')
    message = str(info.value)
    assert 'test.ckpt' in message and '1.weight' in message and 'extra' in message
    assert 'shape of 0.bias: model [3], checkpoint [4]' in message
    assert torch.equal(module[0].weight, before)


def test_allowed_missing_prefixes_keep_their_values() -> None:
    """Keys under allow_missing may be absent; the rest is loaded."""
    module = nn.Sequential(nn.Linear(2, 3), nn.Linear(3, 1))
    kept = module[1].weight.clone()
    state = {'0.weight': torch.ones(3, 2), '0.bias': torch.zeros(3)}
    report = load_state_dict_checked(module, state, 'partial', allow_missing=('1.',))
    assert report.missing == ('1.weight', '1.bias') and report.matched == 2
    assert torch.equal(module[0].weight, torch.ones(3, 2))
    assert torch.equal(module[1].weight, kept)
    with pytest.raises(CheckpointError, match='missing'):
        load_state_dict_checked(module, state, 'partial')


def test_loading_a_missing_directory_fails_clearly(tmp_path) -> None:
    """A directory without a config raises a configuration error naming the path."""
    with pytest.raises(Exception, match='config.yaml'):
        load_checkpoint(tmp_path / 'nothing')
