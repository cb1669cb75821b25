"""Hand-branch configurations: the shipped YAML files load, bad values are named."""

from pathlib import Path

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.model.hand.config import AppearanceViTConfig
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.hand.config import load_hand_branch_config
import pytest


def test_paper_config_has_wilor_sizes() -> None:
    config = load_hand_branch_config('paper')
    vit = config.appearance
    assert config.crop_size == 256
    assert (vit.image_height, vit.image_width, vit.patch_size) == (256, 192, 16)
    assert (vit.embed_dim, vit.depth, vit.num_heads) == (1280, 32, 16)
    assert vit.grid_size == (16, 12) and config.appearance_offset == (0, 32)


def test_tiny_config_is_small() -> None:
    config = load_hand_branch_config('tiny')
    assert config.crop_size == 128
    assert (config.appearance.embed_dim, config.appearance.depth) == (192, 4)
    assert config.appearance.grid_size == (8, 6)


def test_unknown_name_is_rejected() -> None:
    with pytest.raises(ConfigError, match='paper'):
        load_hand_branch_config('huge')


def test_unknown_key_is_rejected(tmp_path: Path) -> None:
    path = tmp_path / 'bad.yaml'
    path.write_text('hand_branch:\n  crop_size: 128\n  crop_szie: 3\n')
    with pytest.raises(ConfigError, match='crop_szie'):
        load_hand_branch_config(path)


def test_appearance_input_must_fit_the_crop() -> None:
    with pytest.raises(ConfigError, match='must fit centred'):
        HandBranchConfig(crop_size=128)  # default appearance input is 256 x 192


@pytest.mark.parametrize('kwargs, message', [
    ({'image_height': 250}, 'not a multiple of patch_size'),
    ({'patch_padding': 8}, 'patch_padding'),
    ({'num_heads': 7}, 'not divisible by num_heads'),
    ({'depth': 0}, 'depth: must be positive'),
])
def test_bad_vit_sizes_are_named(kwargs: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        AppearanceViTConfig(**kwargs)
