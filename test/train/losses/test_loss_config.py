"""Tests of train/losses/loss_config.py: the shipped file, defaults and refused values."""

from pathlib import Path

from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import dump_config
from infinihand_ros.core.config import load_config
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.train.losses import CameraLossConfig
from infinihand_ros.train.losses import load_loss_config
from infinihand_ros.train.losses import LossConfig
from infinihand_ros.train.losses import LOSSES_SECTION
from infinihand_ros.train.losses import MaskLossConfig
from infinihand_ros.train.losses import WorldJointLossConfig
import pytest


def test_shipped_file_is_complete_and_matches_the_documented_defaults() -> None:
    """config/train_losses.yaml gives every field and the dataclass defaults agree with it."""
    path = config_dir() / 'train_losses.yaml'
    loaded = load_config(path, LOSSES_SECTION, LossConfig, require_complete=True)
    assert loaded == LossConfig()
    assert load_loss_config() == loaded


def test_dump_round_trips(tmp_path: Path, config: LossConfig) -> None:
    """A dumped config loads back to the same values (as a checkpoint's saved config would)."""
    path = tmp_path / 'losses.yaml'
    path.write_text(dump_config(config, LOSSES_SECTION))
    assert load_loss_config(path) == config


@pytest.mark.parametrize(('text', 'message'), [
    ('losses: {camera: {rel_translation_weight: -1}}',
     r'losses.camera.rel_translation_weight: must be >= 0.0, got -1.0'),
    ('losses: {mask: {bce_weight: .nan}}', r'losses.mask.bce_weight: must be a finite number'),
    ('losses: {world_joints: {epsilon: 0}}', r'losses.world_joints.epsilon: must be positive'),
    ('losses: {rotation_clamp_eps: 1.0}', r'losses.rotation_clamp_eps: must be below 1'),
    ('losses: {min_scale_m: 0}', r'losses.min_scale_m: must be positive'),
    ('losses: {mano: {min_depth_m: 0.0}}', r'losses.mano.min_depth_m: must be positive'),
    ('losses: {landmarks: {max_abs: 0}}', r'losses.landmarks.max_abs: must be positive'),
    ('losses: {camera: {wieght: 1}}', r"unknown key\(s\) \['wieght'\]"),
    ('losses: {temporal: {weight: yes}}', r'losses.temporal.weight: expected a number'),
])
def test_bad_values_name_the_key(tmp_path: Path, text: str, message: str) -> None:
    """Each refused value raises ConfigError naming the dotted key and the value."""
    path = tmp_path / 'losses.yaml'
    path.write_text(text + '\n')
    with pytest.raises(ConfigError, match=message):
        load_loss_config(path)


def test_zero_weights_are_allowed() -> None:
    """A weight of 0 switches a term off; it is not an error."""
    assert MaskLossConfig(bce_weight=0.0).bce_weight == 0.0
    assert CameraLossConfig(rel_weight=0.0).rel_weight == 0.0
    with pytest.raises(ConfigError, match='losses.world_joints.weight'):
        WorldJointLossConfig(weight=float('inf'))
