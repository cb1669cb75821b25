"""Builders of the whole-model checkpoint tests: a micro InfiniHand model and its inputs."""

from dataclasses import replace

from infinihand_ros.model.config import AggregatorConfig
from infinihand_ros.model.config import CameraHeadConfig
from infinihand_ros.model.config import DptConfig
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.config import MemoryConfig
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.infinihand_model import InfiniHandModel
import pytest


def micro_geometry_config() -> GeometryConfig:
    """Return a geometry config for fast CPU tests: 56x70 images (4x5 patches), 64-d, 2 blocks."""
    aggregator = AggregatorConfig(image_height=56, image_width=70, embed_dim=64, depth=2,
                                  num_heads=2, rope3d_split=(12, 10, 10),
                                  selected_layers=(0, 1, 1, 1))
    return GeometryConfig(aggregator=aggregator,
                          camera_head=CameraHeadConfig(trunk_depth=1, num_heads=2,
                                                       num_iterations=2),
                          dpt=DptConfig(features=16, out_channels=(16, 16, 32, 32),
                                        head_features=8),
                          memory=replace(MemoryConfig(), anchor_frames=1, window=2))


@pytest.fixture(scope='session')
def geometry_config() -> GeometryConfig:
    """Return the micro geometry config."""
    return micro_geometry_config()


@pytest.fixture(scope='session')
def hand_config() -> HandBranchConfig:
    """Return the shipped tiny hand-branch config (4-layer 192-d appearance ViT)."""
    return load_hand_branch_config('tiny')


@pytest.fixture
def model(geometry_config: GeometryConfig, hand_config: HandBranchConfig) -> InfiniHandModel:
    """Return a micro model seeded with 0, in eval mode."""
    return build_infinihand_model(geometry_config, hand_config, seed=0).eval()
