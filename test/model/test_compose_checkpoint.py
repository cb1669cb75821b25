"""Tests of model/io/compose.py: converted LingBot-Map + WiLoR parts load into one model."""

from dataclasses import replace
from pathlib import Path

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.hand.appearance_vit import AppearanceViT
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.heads.mask_head import FINAL_LAYER_PREFIX
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.model.io.checkpoint import config_to_yaml
from infinihand_ros.model.io.checkpoint import read_safetensors
from infinihand_ros.model.io.checkpoint import save_infinihand_checkpoint
from infinihand_ros.model.io.checkpoint import WEIGHTS_FILE
from infinihand_ros.model.io.compose import load_composed_model
from infinihand_ros.model.io.convert_lingbot_map import convert_checkpoint
from infinihand_ros.model.io.convert_wilor import convert_wilor
import pytest
from safetensors.torch import save_file
import torch

UPSTREAM = ('aggregator.', 'camera_head.', 'depth_head.')


def _lingbot_map_part(config: GeometryConfig, tmp_path: Path) -> tuple[Path, dict]:
    """Convert a random LingBot-Map-layout checkpoint of ``config``; return its dir and tensors."""
    with torch.device('meta'):
        shapes = {key: value.shape for key, value in GeometryModel(config).state_dict().items()}
    generator = torch.Generator().manual_seed(5)
    state = {key: torch.randn(shape, generator=generator) for key, shape in shapes.items()
             if key.startswith(UPSTREAM)}
    torch.save({'model': state}, tmp_path / 'lingbot-map.pt')
    (tmp_path / 'geometry.yaml').write_text(config_to_yaml(config), encoding='utf-8')
    convert_checkpoint('lingbot-map', tmp_path / 'lingbot-map.pt', tmp_path / 'geometry.yaml',
                       tmp_path / 'geometry_part')
    return tmp_path / 'geometry_part', state


def _wilor_part(hand_config: HandBranchConfig, tmp_path: Path) -> tuple[Path, dict]:
    """Convert a fake WiLoR checkpoint of ``hand_config``'s ViT; return its dir and tensors."""
    torch.manual_seed(1)
    vit = AppearanceViT(hand_config.appearance, default_cam_scale=5.0)
    backbone = {f'backbone.{key}': value for key, value in vit.state_dict().items()}
    torch.save({'state_dict': {**backbone, 'mano.faces': torch.zeros(2, 3)}},
               tmp_path / 'wilor.ckpt')
    convert_wilor(tmp_path / 'wilor.ckpt', tmp_path / 'crop_part', hand_config)
    return tmp_path / 'crop_part', backbone


@pytest.fixture
def parts(geometry_config: GeometryConfig, hand_config: HandBranchConfig,
          tmp_path) -> tuple[Path, dict, Path, dict]:
    """Return (geometry dir, its upstream tensors, crop-encoder dir, WiLoR backbone tensors)."""
    return (*_lingbot_map_part(geometry_config, tmp_path), *_wilor_part(hand_config, tmp_path))


def test_lingbot_map_and_wilor_compose_the_rest_seeded(parts, geometry_config: GeometryConfig,
                                                       hand_config: HandBranchConfig) -> None:
    geometry_dir, upstream, crop_dir, backbone = parts
    model, report = load_composed_model(geometry=geometry_dir, crop_encoder=crop_dir, seed=4)
    assert not model.training and report.ok
    state = model.state_dict()
    for key, tensor in upstream.items():
        assert torch.equal(state[f'geometry.{key}'], tensor), key
    for key, tensor in backbone.items():
        assert torch.equal(state[f'hand_branch.{key}'], tensor), key
    for key, tensor in model.geometry.mask_head.state_dict().items():
        depth = upstream[f'depth_head.{key}']
        assert torch.equal(tensor, depth) != key.startswith(FINAL_LAYER_PREFIX), key
    seeded = build_infinihand_model(model.geometry.config, hand_config, seed=4).state_dict()
    for key, tensor in state.items():
        if key.startswith(('hand_branch.adapter', 'hand_branch.fusion', 'hand_branch.mano_head',
                           'hand_branch.landmark_head', 'hand_branch.hand_models')):
            assert torch.equal(tensor, seeded[key]), key
    geometry, hands = report.branch('geometry'), report.branch('hand_branch')
    assert list(geometry.loaded.values()) == [len(upstream)]
    assert str(geometry_dir) in next(iter(geometry.loaded))
    assert 'lingbot-map: lingbot-map.pt' in next(iter(geometry.loaded))
    assert geometry.seeded == () and list(geometry.derived) == ['geometry.mask_head']
    assert list(hands.loaded.values()) == [len(backbone)]
    assert hands.seeded == ('hand_branch.adapter', 'hand_branch.fusion',
                            'hand_branch.landmark_head', 'hand_branch.mano_head')
    text = report.describe()
    assert 'geometry.mask_head: seeded from the loaded geometry.depth_head' in text
    assert 'hand_models' not in text and 'missing' not in text
    assert model.geometry.config.preprocessing == 'resize_crop'
    assert replace(model.geometry.config, preprocessing='letterbox') == geometry_config


def test_mask_head_seeding_is_reproducible_and_keeps_the_callers_random_state(parts) -> None:
    geometry_dir, _, crop_dir, _ = parts
    torch.manual_seed(11)
    expected_draw = torch.rand(3)
    torch.manual_seed(11)
    first, _ = load_composed_model(geometry=geometry_dir, crop_encoder=crop_dir, seed=4)
    assert torch.equal(torch.rand(3), expected_draw)
    second, _ = load_composed_model(geometry=geometry_dir, crop_encoder=crop_dir, seed=4)
    for key, tensor in first.state_dict().items():
        assert torch.equal(tensor, second.state_dict()[key]), key


def test_parts_override_a_full_checkpoint(parts, model: InfiniHandModel, tmp_path) -> None:
    geometry_dir, upstream, crop_dir, backbone = parts
    full = save_infinihand_checkpoint(model, tmp_path / 'full')
    composed, report = load_composed_model(full=full, geometry=geometry_dir)
    state = composed.state_dict()
    assert torch.equal(state['geometry.depth_head.norm.weight'],
                       upstream['depth_head.norm.weight'])
    assert torch.equal(state['hand_branch.backbone.pos_embed'],
                       model.state_dict()['hand_branch.backbone.pos_embed'])
    assert report.config_sources['hand_branch'] == f'{full} (full)'
    assert report.config_sources['geometry'] == f'{geometry_dir} (geometry)'
    with_crop, crop_report = load_composed_model(full=full, crop_encoder=crop_dir)
    assert torch.equal(with_crop.state_dict()['hand_branch.backbone.pos_embed'],
                       backbone['backbone.pos_embed'])
    counts = crop_report.branch('hand_branch').loaded
    assert sorted(counts.values()) == sorted(
        [len(backbone), sum(key.startswith('hand_branch.') for key in state) - 4 - len(backbone)])


def test_differences_are_listed_by_branch(
        parts, geometry_config: GeometryConfig, tmp_path) -> None:
    geometry_dir, _, crop_dir, _ = parts
    tensors = read_safetensors(geometry_dir / WEIGHTS_FILE)
    tensors['geometry.depth_head.norm.weight'] = torch.zeros(3)
    del tensors['geometry.camera_head.token_norm.weight']
    tensors['geometry.mask_head.norm.weight'] = torch.zeros(128)  # a partial mask head
    save_file(tensors, geometry_dir / WEIGHTS_FILE)
    crop = read_safetensors(crop_dir / WEIGHTS_FILE)
    crop['hand_branch.fusion.bias'] = torch.zeros(1)
    save_file(crop, crop_dir / WEIGHTS_FILE)
    with pytest.raises(CheckpointError) as info:
        load_composed_model(geometry=geometry_dir, crop_encoder=crop_dir)
    message = str(info.value)
    geometry_part, hand_part = message.split('\nhand_branch:')
    assert 'shape of geometry.depth_head.norm.weight: model [128], checkpoint [3]' \
        in geometry_part
    assert 'missing: geometry.camera_head.token_norm.weight' in geometry_part
    assert 'geometry.mask_head.norm.bias' in geometry_part  # the rest of a partial mask head
    assert 'unexpected: hand_branch.fusion.bias' in hand_part


def test_misplaced_parts_and_missing_configs_are_named(parts, model: InfiniHandModel,
                                                       hand_config: HandBranchConfig,
                                                       tmp_path) -> None:
    geometry_dir, _, crop_dir, _ = parts
    with pytest.raises(CheckpointError, match='not a full checkpoint.*pass it as geometry='):
        load_composed_model(full=geometry_dir)
    with pytest.raises(CheckpointError, match='not a crop_encoder checkpoint'):
        load_composed_model(crop_encoder=geometry_dir, hand_config=hand_config)
    with pytest.raises(CheckpointError, match='no hand-branch config.*pass hand_config'):
        load_composed_model(geometry=geometry_dir)
    other = replace(hand_config, appearance=replace(hand_config.appearance, depth=1))
    full = save_infinihand_checkpoint(build_infinihand_model(model.geometry.config, other),
                                      tmp_path / 'other')
    with pytest.raises(CheckpointError, match='appearance ViT config differs'):
        load_composed_model(full=full, crop_encoder=crop_dir)
