"""Builders shared by the model tests: very small geometry configurations and models."""

from collections.abc import Callable
from dataclasses import replace

from infinihand_ros.model.config import AggregatorConfig
from infinihand_ros.model.config import CameraHeadConfig
from infinihand_ros.model.config import DptConfig
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.config import MemoryConfig
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.infinihand_model import InfiniHandModel
import pytest
import torch


ROPE3D_SPLITS = {64: (12, 10, 10), 96: (16, 16, 16)}


def micro_config(embed_dim: int = 64, **memory: int) -> GeometryConfig:
    """Return a geometry config small enough for per-test CPU runs (4x5 patches of 14 px).

    Args:
        embed_dim: 64 or 96 (two heads).
        **memory: ``MemoryConfig`` overrides (anchor_frames, window).

    """
    aggregator = AggregatorConfig(image_height=56, image_width=70, embed_dim=embed_dim, depth=2,
                                  num_heads=2, rope3d_split=ROPE3D_SPLITS[embed_dim],
                                  selected_layers=(0, 1, 1, 1))
    return GeometryConfig(aggregator=aggregator,
                          camera_head=CameraHeadConfig(trunk_depth=1, num_heads=2,
                                                       num_iterations=2),
                          dpt=DptConfig(features=16, out_channels=(16, 16, 32, 32),
                                        head_features=8),
                          memory=replace(MemoryConfig(), **memory))


@pytest.fixture
def micro_model() -> GeometryModel:
    """Return a seeded micro model (anchor 2, window 2) in eval mode."""
    torch.manual_seed(0)
    return GeometryModel(micro_config(anchor_frames=2, window=2)).eval()


@pytest.fixture
def make_micro_config() -> Callable[..., GeometryConfig]:
    """Return the ``micro_config`` builder (embed_dim 64 or 96, memory overrides)."""
    return micro_config


@pytest.fixture(scope='session')
def geometry_config() -> GeometryConfig:
    """Return the micro geometry config of the whole-model tests (anchor 1, window 2)."""
    return micro_config(anchor_frames=1, window=2)


@pytest.fixture(scope='session')
def hand_config() -> HandBranchConfig:
    """Return the shipped tiny hand-branch config (4-layer 192-d appearance ViT)."""
    return load_hand_branch_config('tiny')


@pytest.fixture
def model(geometry_config: GeometryConfig, hand_config: HandBranchConfig) -> InfiniHandModel:
    """Return a micro InfiniHand model seeded with 0, in eval mode."""
    return build_infinihand_model(geometry_config, hand_config, seed=0).eval()
