"""Training configs: the shipped files load, round-trip, compose, and bad values name their key."""

import dataclasses
from pathlib import Path

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.train.config_compose import parse_override
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
    document = yaml.safe_load((CONFIG_DIR / f'train_{name}.yaml').read_text())
    if 'losses' not in document and 'base' not in document:
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


def test_the_heads_config_is_its_base_plus_the_heads_setting() -> None:
    """train_tiny_heads.yaml: Stage I (train_tiny.yaml) with the backbone and depth frozen."""
    base, heads = load_train_config('tiny'), load_train_config('tiny_heads')
    assert heads == dataclasses.replace(
        base, optim=heads.optim, loss_groups=('mask', 'landmarks', 'mano'),
        box_jitter=heads.box_jitter, photometric=heads.photometric, horizontal_flip=0.5)
    assert {group.name: group.lr for group in heads.optim.groups} == {
        'mask': 2e-4, 'landmarks': 2e-4, 'mano': 1e-4}
    assert {'geometry.aggregator', 'geometry.camera_head', 'geometry.depth_head'} <= set(
        heads.optim.frozen)
    assert heads.box_jitter.enabled and heads.photometric.brightness == 0.4
    assert heads.optim.warmup_steps == base.optim.warmup_steps  # inherited
    assert CONFIG_DIR.joinpath('train_tiny_heads.yaml').read_text().count('\n') < 30


def _write_yaml(path: Path, document: dict) -> Path:
    path.write_text(yaml.safe_dump(document), encoding='utf-8')
    return path


def test_a_base_is_deep_merged_and_relative_to_the_file(tmp_path: Path) -> None:
    """Mappings merge key by key, lists and values replace, bases chain; base is not saved."""
    _write_yaml(tmp_path / 'a.yaml', {'train': {'steps': 7, 'clip': {'anchor_frames': 2},
                                                'loss_groups': ['mask', 'mano']},
                                      'losses': {'camera': {'weight': 3.0}}})
    (tmp_path / 'sub').mkdir()
    _write_yaml(tmp_path / 'sub' / 'b.yaml', {'base': '../a.yaml',
                                              'train': {'clip': {'clip_step': 3}}})
    top = _write_yaml(tmp_path / 'sub' / 'c.yaml', {'base': 'b.yaml',
                                                    'train': {'loss_groups': ['mask']},
                                                    'losses': {'mask': {'bce_weight': 2.0}}})
    config = load_train_config(top)
    assert (config.steps, config.clip.anchor_frames, config.clip.clip_step) == (7, 2, 3)
    assert config.loss_groups == ('mask',)
    assert (config.losses.camera.weight, config.losses.mask.bce_weight) == (3.0, 2.0)
    assert 'base' not in train_config_to_yaml(config)


def test_base_errors_name_the_file(tmp_path: Path) -> None:
    _write_yaml(tmp_path / 'a.yaml', {'base': 'b.yaml', 'train': {}})
    _write_yaml(tmp_path / 'b.yaml', {'base': 'a.yaml', 'train': {}})
    with pytest.raises(ConfigError, match='form a cycle'):
        load_train_config(tmp_path / 'a.yaml')
    with pytest.raises(ConfigError, match=r'missing\.yaml: cannot read'):
        load_train_config(_write_yaml(tmp_path / 'c.yaml', {'base': 'missing.yaml'}))
    with pytest.raises(ConfigError, match=r'c\.yaml:base: expected a file name'):
        load_train_config(_write_yaml(tmp_path / 'c.yaml', {'base': 3, 'train': {}}))
    with pytest.raises(ConfigError, match=r"unknown top-level key\(s\) \['bsae'\]"):
        load_train_config(_write_yaml(tmp_path / 'c.yaml', {'bsae': 'a.yaml', 'train': {}}))


def test_dotted_overrides_set_typed_values() -> None:
    overrides = dict(parse_override(text) for text in (
        'train.steps=5', 'train.data.sequences=[a, b]', 'losses.camera.weight=5.0',
        'train.box_jitter={scale: 0.2, shift: 0.1}', 'train.model.init_checkpoint=null'))
    config = load_train_config('tiny_heads', overrides)
    assert config.steps == 5 and config.data.sequences == ('a', 'b')
    assert config.losses.camera.weight == 5.0 and config.box_jitter.scale == 0.2
    assert config.model.init_checkpoint is None
    assert config.optim == load_train_config('tiny_heads').optim  # the rest as the file says


@pytest.mark.parametrize('text, message', [
    ('train.steps', r'expected KEY=VALUE'),
    ('=3', r'expected KEY=VALUE'),
    ('steps=3', r'starts with one of \[\'losses\', \'train\'\]'),
    ('train.stpes=3', r"train has no key 'stpes'; valid keys are"),
    ('train.clip.anchors=3', r"train\.clip has no key 'anchors'"),
    ('train.steps.max=3', r'train\.steps is a value, not a section'),
    ('train.steps=three', r'train\.steps: expected int'),
    ('losses.mask.bce_weight=-1.0', r'losses\.mask\.bce_weight'),
    ('train.data.sequences=[a', r'--set train\.data\.sequences: the value .* is not YAML'),
])
def test_bad_overrides_name_their_key(text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        load_train_config('tiny', dict([parse_override(text)]))
