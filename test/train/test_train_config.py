"""Training configs: the shipped files load, round-trip, and bad values name their key."""

import dataclasses
from pathlib import Path

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.train.losses import load_loss_config
from infinihand_ros.train.train_config import ClipLayout
from infinihand_ros.train.train_config import load_train_config
from infinihand_ros.train.train_config import train_config_to_yaml
from infinihand_ros.train.train_config import TrainConfig
import pytest
import yaml


CONFIG_DIR = Path(__file__).parents[2] / 'config'
#: Every shipped training config by name (train_losses.yaml holds loss weights, not a run).
SHIPPED_NAMES = sorted(path.stem.removeprefix('train_') for path in CONFIG_DIR.glob('train_*.yaml')
                       if path.name != 'train_losses.yaml')


@pytest.mark.parametrize('name', SHIPPED_NAMES)
def test_shipped_configs_load_and_round_trip(name: str, tmp_path: Path) -> None:
    config = load_train_config(name)
    if 'losses' not in yaml.safe_load((CONFIG_DIR / f'train_{name}.yaml').read_text()):
        assert config.losses == load_loss_config()  # no losses section: train_losses.yaml's
    path = tmp_path / 'resolved.yaml'
    path.write_text(train_config_to_yaml(config), encoding='utf-8')
    assert load_train_config(path) == config


def test_paper_configs_follow_the_paper() -> None:
    """Sec. 4.1: AdamW 0.01, clip 1.0, per-stage rates, 4-frame and 4 + 16 x 2 clips."""
    stage1, stage2 = load_train_config('paper'), load_train_config('paper_stage2')
    rates = {group.name: group.lr for group in stage1.optim.groups}
    assert rates['mask'] == rates['landmarks'] == 1e-4 and rates['mano'] == 5e-5
    assert {group.name: group.lr for group in stage2.optim.groups} == {'camera': 3e-5,
                                                                       'rest': 1e-5}
    assert stage1.clip.total_frames == 4 and stage2.clip.total_frames == 36
    assert stage2.clip.blocks == ((0, 4), (4, 20), (20, 36))
    for config in (stage1, stage2):
        assert config.optim.weight_decay == 0.01 and config.optim.grad_clip_norm == 1.0
    assert stage1.steps == 300_000 and stage2.steps == 100_000
    assert stage2.gt_box_ratio == 0.5 and len(stage2.loss_groups) == 6
    assert 'depth' not in stage1.loss_groups + stage2.loss_groups  # pretrained depth


def test_tiny_configs_add_the_depth_term_and_train_the_depth_head() -> None:
    """The tiny model has no pretrained depth: both stages supervise it (ours)."""
    for name in ('tiny', 'tiny_stage2'):
        config = load_train_config(name)
        assert 'depth' in config.loss_groups
        assert 'geometry.depth_head' not in config.optim.frozen


def _write(tmp_path: Path, train: dict, **sections: object) -> Path:
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump({'train': train, **sections}), encoding='utf-8')
    return path


@pytest.mark.parametrize('train, message', [
    ({'batch_size': 'two'}, r'train\.batch_size: expected int'),
    ({'clip': {'anchors': 4}}, r'train\.clip: unknown key\(s\) \[\'anchors\'\]'),
    ({'stage': 'stage3'}, r'train\.stage: must be one of'),
    ({'clip': {'anchor_frames': 0}}, r'train\.clip\.anchor_frames: must be positive'),
    ({'optim': {'groups': [{'name': 'a', 'lr': -1.0}]}},
     r'train\.optim\.groups\[a\]\.lr: must be positive'),
    ({'optim': {'betas': [0.9, 1.5]}}, r'train\.optim\.betas'),
    ({'gt_box_ratio': 1.5}, r'train\.gt_box_ratio'),
    ({'loss_groups': ['mask', 'normals']}, r'train\.loss_groups: must be one of'),
    ({'stage': 'stage1', 'loss_groups': ['mask', 'camera']}, r"\['camera'\] need Stage II"),
    ({'losses': {}}, r'top-level \'losses\' section'),
])
def test_bad_values_name_their_key(tmp_path: Path, train: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        load_train_config(_write(tmp_path, train))


def test_a_losses_section_is_used_and_checked(tmp_path: Path) -> None:
    config = load_train_config(_write(tmp_path, {}, losses={'mask': {'bce_weight': 3.0}}))
    assert config.losses.mask.bce_weight == 3.0
    with pytest.raises(ConfigError, match=r'losses\.mask\.bce_weight'):
        load_train_config(_write(tmp_path, {}, losses={'mask': {'bce_weight': -1.0}}))


def test_missing_file_and_section_are_reported(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match='cannot read'):
        load_train_config(tmp_path / 'none.yaml')
    path = tmp_path / 'empty.yaml'
    path.write_text('other: {}\n', encoding='utf-8')
    with pytest.raises(ConfigError, match="no top-level section 'train'"):
        load_train_config(path)


def test_clip_layout_blocks() -> None:
    layout = ClipLayout(anchor_frames=2, window_frames=4, num_windows=2)
    assert layout.total_frames == 10 and layout.blocks == ((0, 2), (2, 6), (6, 10))
    assert ClipLayout(anchor_frames=4, window_frames=0, num_windows=0).blocks == ((0, 4),)
    assert dataclasses.replace(TrainConfig(), steps=5).steps == 5
