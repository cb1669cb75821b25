"""Tests of model/infinihand_model.py: seeded building, branch compatibility, config names."""

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import InputError
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.hand.hand_branch import HandBranch
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.model.infinihand_model import load_branch_configs
from infinihand_ros.model.io.checkpoint import config_to_yaml
import pytest
import torch


def test_building_is_seeded_and_leaves_the_global_generator_alone(
        geometry_config: GeometryConfig, hand_config: HandBranchConfig) -> None:
    torch.manual_seed(123)
    expected_next = torch.rand(3)
    torch.manual_seed(123)
    first = build_infinihand_model(geometry_config, hand_config, seed=5)
    assert torch.equal(torch.rand(3), expected_next)
    second = build_infinihand_model(geometry_config, hand_config, seed=5)
    other = build_infinihand_model(geometry_config, hand_config, seed=6)
    key = 'hand_branch.fusion.weight'
    assert torch.equal(first.state_dict()[key], second.state_dict()[key])
    assert not torch.equal(first.state_dict()[key], other.state_dict()[key])


def test_feature_width_must_match(geometry_config: GeometryConfig,
                                  hand_config: HandBranchConfig) -> None:
    with torch.device('meta'):
        geometry = GeometryModel(geometry_config)
        hand_branch = HandBranch(hand_config, feature_dim=64)
    with pytest.raises(ConfigError, match='built for 64-d features, but the geometry branch '
                                          'gives 128-d'):
        InfiniHandModel(geometry, hand_branch)


def test_configs_load_by_name_or_path(geometry_config: GeometryConfig, tmp_path) -> None:
    tiny_geometry, tiny_hand = load_branch_configs('tiny', 'tiny')
    assert tiny_geometry.aggregator.embed_dim == 192
    assert tiny_hand.appearance.embed_dim == 192
    path = tmp_path / 'micro.yaml'
    path.write_text(config_to_yaml(geometry_config), encoding='utf-8')
    assert load_branch_configs(path, 'tiny')[0] == geometry_config
    with pytest.raises(ConfigError, match='model_huge.yaml'):
        load_branch_configs('huge', 'tiny')


def test_geometry_without_the_mask_head_gives_the_same_other_outputs(
        model: InfiniHandModel) -> None:
    """masks=False skips only the mask head; finding hands then needs given boxes."""
    config = model.geometry.config.aggregator
    images = torch.rand(1, 3, 3, config.image_height, config.image_width,
                        generator=torch.Generator().manual_seed(0))
    with torch.inference_mode():
        full, poses, used = model.run_geometry(images, model.new_stream())
        skipped, skipped_poses, _ = model.run_geometry(images, model.new_stream(), masks=False)
        with pytest.raises(InputError, match='without the mask head'):
            model.run_hands(images, skipped, skipped_poses, used)
    assert skipped.hand_masks is None and full.hand_masks is not None
    torch.testing.assert_close(skipped_poses, poses, rtol=0, atol=0)
    for name in ('pose_encoding', 'depth', 'depth_conf', 'patch_features'):
        torch.testing.assert_close(getattr(skipped, name), getattr(full, name), rtol=0, atol=0)
