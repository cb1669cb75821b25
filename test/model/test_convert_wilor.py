"""Tests of model/io/convert_wilor.py with fake WiLoR checkpoints built from our tiny ViT."""

import json
from pathlib import Path

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.hand.appearance_vit import AppearanceViT
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.io.checkpoint import read_checkpoint
from infinihand_ros.model.io.compose import load_composed_model
from infinihand_ros.model.io.convert_wilor import check_wilor_backbone
from infinihand_ros.model.io.convert_wilor import convert_wilor
from infinihand_ros.model.io.convert_wilor import group_unused_keys
from infinihand_ros.model.io.convert_wilor import main
import pytest
import torch

WILOR_KEYS = Path('/work/shared/design/keys/wilor_backbone.json')
EXTRAS = {'refine_net.dec_layers.0.weight': torch.ones(4, 2),
          'refine_net.bn.running_mean': torch.zeros(4),
          'mano.faces_tensor': torch.zeros(3, 3, dtype=torch.long),
          'discriminator.D_conv1.weight': torch.ones(2, 2),
          'initialized': torch.tensor(True)}


class TrainingObject:
    """A non-tensor object as Lightning checkpoints hold in their hyper-parameters."""


def _fake_backbone(hand_config: HandBranchConfig) -> dict[str, torch.Tensor]:
    """Return a tiny appearance ViT's state dict under WiLoR's ``backbone.`` prefix (seed 1)."""
    torch.manual_seed(1)
    vit = AppearanceViT(hand_config.appearance, default_cam_scale=5.0)
    return {f'backbone.{key}': value for key, value in vit.state_dict().items()}


def _write(content: object, path: Path) -> Path:
    torch.save(content, path)
    return path


WRAPPINGS = {
    'lightning': lambda state: {'state_dict': state, 'epoch': 7, 'global_step': 100},
    'plain': lambda state: state,
    'data_parallel': lambda state: {f'module.{key}': value for key, value in state.items()},
}


@pytest.mark.parametrize('wrapping', sorted(WRAPPINGS))
def test_backbone_becomes_a_crop_encoder_checkpoint(wrapping: str,
                                                    geometry_config: GeometryConfig,
                                                    hand_config: HandBranchConfig,
                                                    tmp_path) -> None:
    backbone = _fake_backbone(hand_config)
    source = _write(WRAPPINGS[wrapping]({**backbone, **EXTRAS}), tmp_path / 'wilor.ckpt')
    conversion = convert_wilor(source, tmp_path / 'out', hand_config)
    written = read_checkpoint(tmp_path / 'out')
    assert written.hand_config == hand_config and written.geometry_config is None
    assert written.tensors.keys() == {f'hand_branch.{key}' for key in backbone}
    assert written.metadata['source'] == 'wilor: wilor.ckpt'
    assert conversion.report.exact and conversion.report.matched == len(backbone)
    assert conversion.unused == {
        'refine_net': ('refine_net.dec_layers.0.weight', 'refine_net.bn.running_mean'),
        'mano': ('mano.faces_tensor',), 'discriminator': ('discriminator.D_conv1.weight',),
        'other': ('initialized',)}
    loaded, report = load_composed_model(crop_encoder=tmp_path / 'out',
                                         geometry_config=geometry_config, seed=2)
    state = loaded.state_dict()
    for key, tensor in backbone.items():
        assert torch.equal(state[f'hand_branch.{key}'], tensor), key
    seeded = build_infinihand_model(geometry_config, hand_config, seed=2).state_dict()
    for key, tensor in seeded.items():
        if not key.startswith('hand_branch.backbone.'):
            assert torch.equal(state[key], tensor), key
    assert report.branch('hand_branch').seeded == (
        'hand_branch.adapter', 'hand_branch.fusion', 'hand_branch.landmark_head',
        'hand_branch.mano_head')


def test_shape_mismatch_names_the_key(hand_config: HandBranchConfig, tmp_path) -> None:
    backbone = _fake_backbone(hand_config)
    backbone['backbone.pos_embed'] = torch.zeros(1, 193, 1280)
    source = _write({'state_dict': backbone}, tmp_path / 'wilor.ckpt')
    with pytest.raises(CheckpointError) as info:
        convert_wilor(source, tmp_path / 'out', hand_config)
    message = str(info.value)
    assert 'shape of backbone.pos_embed: model [1, 49, 192], checkpoint [1, 193, 1280]' in message
    assert '--hand-branch paper' in message
    assert not (tmp_path / 'out').exists()


def test_missing_backbone_key_is_named(hand_config: HandBranchConfig, tmp_path) -> None:
    backbone = _fake_backbone(hand_config)
    del backbone['backbone.last_norm.bias']
    source = _write(backbone, tmp_path / 'wilor.ckpt')
    with pytest.raises(CheckpointError, match='missing: backbone.last_norm.bias'):
        convert_wilor(source, tmp_path / 'out', hand_config)


def test_unreadable_checkpoints_fail_clearly(hand_config: HandBranchConfig, tmp_path) -> None:
    def convert(path: Path) -> None:
        convert_wilor(path, tmp_path / 'out', hand_config)

    with pytest.raises(CheckpointError, match='no such WiLoR checkpoint file'):
        convert(tmp_path / 'absent.ckpt')
    refused = _write({'state_dict': _fake_backbone(hand_config),
                      'hyper_parameters': TrainingObject()}, tmp_path / 'objects.ckpt')
    with pytest.raises(CheckpointError, match='save its "state_dict" entry alone'):
        convert(refused)
    not_tensors = _write({'backbone.pos_embed': [1.0, 2.0]}, tmp_path / 'lists.ckpt')
    with pytest.raises(CheckpointError, match='not tensors'):
        convert(not_tensors)


@pytest.mark.skipif(not WILOR_KEYS.is_file(), reason='WiLoR key reference not available')
def test_real_wilor_keys_map_by_identity_and_group() -> None:
    reference = json.loads(WILOR_KEYS.read_text())['keys']
    assert sum(key.startswith('backbone.') for key in reference) == 404
    state = {key: torch.empty(shape, device='meta') for key, shape in reference.items()}
    check_wilor_backbone(load_hand_branch_config('paper').appearance, state,
                         'wilor_backbone.json')  # raises on any key or shape difference
    del state['backbone.blocks.31.mlp.fc2.bias']
    with pytest.raises(CheckpointError, match='missing: backbone.blocks.31.mlp.fc2.bias'):
        check_wilor_backbone(load_hand_branch_config('paper').appearance, state, 'cut')
    groups = group_unused_keys(state)
    assert len(groups['refine_net']) == 26
    assert not groups['mano'] and not groups['discriminator'] and not groups['other']


def test_cli_converts_and_reports(hand_config: HandBranchConfig, tmp_path, capsys) -> None:
    source = _write({'state_dict': {**_fake_backbone(hand_config), **EXTRAS}},
                    tmp_path / 'wilor.ckpt')
    args = ['--wilor', str(source), '--out', str(tmp_path / 'out'), '--hand-branch', 'tiny']
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert 'unused WiLoR refine_net: 2 keys' in printed
    assert 'hand_branch.backbone.*' in printed
    assert read_checkpoint(tmp_path / 'out').hand_config == hand_config
    with pytest.raises(SystemExit) as info:
        main(args)  # --out exists now
    assert info.value.code == 2
    assert 'already exists' in capsys.readouterr().err
    assert main([*args[:2], '--out', str(tmp_path / 'other'), '--hand-branch', 'huge']) == 1
    assert capsys.readouterr().err.startswith('error: ')
    assert not (tmp_path / 'other').exists()
