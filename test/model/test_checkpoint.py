"""Tests of model/io/checkpoint.py: checked loading and the rules of the checkpoint format."""

import os

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.model.io.checkpoint import checkpoint_tensors
from infinihand_ros.model.io.checkpoint import GEOMETRY_FILE
from infinihand_ros.model.io.checkpoint import HAND_BRANCH_FILE
from infinihand_ros.model.io.checkpoint import load_state_dict_checked
from infinihand_ros.model.io.checkpoint import read_checkpoint
from infinihand_ros.model.io.checkpoint import WEIGHTS_FILE
from infinihand_ros.model.io.checkpoint import write_checkpoint
import pytest
import torch
from torch import nn


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


def test_allowed_missing_keys_keep_their_values_and_stay_out_of_the_report() -> None:
    """Keys under allow_missing may be absent; they are counted apart, never listed."""
    module = nn.Sequential(nn.Linear(2, 3), nn.Linear(3, 1))
    kept = module[1].weight.clone()
    state = {'0.weight': torch.ones(3, 2), '0.bias': torch.zeros(3)}
    report = load_state_dict_checked(module, state, 'partial', allow_missing=('1.',))
    assert report.allowed_missing == ('1.weight', '1.bias') and report.missing == ()
    assert report.matched == 2 and report.ok and not report.exact
    assert torch.equal(module[0].weight, torch.ones(3, 2))
    assert torch.equal(module[1].weight, kept)
    with pytest.raises(CheckpointError, match='missing: 1.weight'):
        load_state_dict_checked(module, state, 'partial')
    bad = {**state, '0.bias': torch.zeros(4)}
    with pytest.raises(CheckpointError) as info:
        load_state_dict_checked(module, bad, 'partial', allow_missing=('1.',))
    assert '1.weight' not in str(info.value) and '2 allowed missing' in str(info.value)


def test_parts_round_trip_with_their_configs(model: InfiniHandModel, tmp_path) -> None:
    """A geometry-only part keeps its keys, config and source; no hand-branch file appears."""
    tensors = {key: value for key, value in checkpoint_tensors(model).items()
               if key.startswith('geometry.')}
    directory = write_checkpoint(tmp_path / 'part', tensors, model.geometry.config,
                                 source='test: weights.pt')
    assert sorted(path.name for path in directory.iterdir()) == [GEOMETRY_FILE, WEIGHTS_FILE]
    umask = os.umask(0o022)
    os.umask(umask)
    for path in directory.iterdir():  # safetensors creates 0600; shared models must be readable
        assert path.stat().st_mode & 0o777 == 0o666 & ~umask, path.name
    contents = read_checkpoint(directory)
    assert contents.geometry_config == model.geometry.config and contents.hand_config is None
    assert contents.source == f'{directory} (test: weights.pt)'
    assert contents.tensors.keys() == tensors.keys()
    assert all(torch.equal(contents.tensors[key], tensor) for key, tensor in tensors.items())


def test_configs_and_tensors_must_belong_together(model: InfiniHandModel, tmp_path) -> None:
    """A branch's tensors need its config and vice versa; MANO data and odd keys are refused."""
    tensors = checkpoint_tensors(model)
    geometry = {key: value for key, value in tensors.items() if key.startswith('geometry.')}
    with pytest.raises(CheckpointError, match='hand_branch.\\* tensors without hand_branch.yaml'):
        write_checkpoint(tmp_path / 'a', tensors, model.geometry.config)
    with pytest.raises(CheckpointError, match='hand_branch.\\* tensors with hand_branch.yaml'):
        write_checkpoint(tmp_path / 'b', geometry, model.geometry.config,
                         model.hand_branch.config)
    for extra in ({'hand_branch.hand_models.0.faces': torch.zeros(1)},
                  {'aggregator.camera_token': torch.zeros(1)}):
        with pytest.raises(CheckpointError, match='never MANO data'):
            write_checkpoint(tmp_path / 'c', {**geometry, **extra}, model.geometry.config)
    assert not any(path.exists() for path in (tmp_path / 'a', tmp_path / 'b', tmp_path / 'c'))


def test_incomplete_or_missing_files_are_refused(model: InfiniHandModel, tmp_path) -> None:
    """A config that leaves out a field, or a directory without weights, fails by name."""
    with pytest.raises(CheckpointError, match='no such checkpoint directory'):
        read_checkpoint(tmp_path / 'absent')
    directory = write_checkpoint(tmp_path / 'ckpt', checkpoint_tensors(model),
                                 model.geometry.config, model.hand_branch.config)
    text = (directory / HAND_BRANCH_FILE).read_text()
    (directory / HAND_BRANCH_FILE).write_text(
        '\n'.join(line for line in text.splitlines() if 'fusion_dim' not in line))
    with pytest.raises(ConfigError, match=r"missing key\(s\) \['fusion_dim'\]"):
        read_checkpoint(directory)
    (directory / WEIGHTS_FILE).unlink()
    with pytest.raises(CheckpointError, match='model.safetensors is missing'):
        read_checkpoint(directory)
