"""Fixtures of the loss tests: a config whose weights all differ."""

from infinihand_ros.train.losses import CameraLossConfig
from infinihand_ros.train.losses import DepthLossConfig
from infinihand_ros.train.losses import LandmarkLossConfig
from infinihand_ros.train.losses import LossConfig
from infinihand_ros.train.losses import ManoLossConfig
from infinihand_ros.train.losses import MaskLossConfig
from infinihand_ros.train.losses import TemporalLossConfig
from infinihand_ros.train.losses import WorldJointLossConfig
import pytest


@pytest.fixture
def config() -> LossConfig:
    """Return a loss config whose weights all differ, so a swapped weight shows."""
    return LossConfig(
        mask=MaskLossConfig(bce_weight=2.0, dice_weight=3.0),
        landmarks=LandmarkLossConfig(weight=0.5, max_abs=1.0),
        mano=ManoLossConfig(orient_weight=1.0, pose_weight=2.0, shape_weight=3.0,
                            trans_weight=4.0, joints_weight=5.0, reproj_weight=6.0,
                            min_depth_m=0.01),
        world_joints=WorldJointLossConfig(weight=1.5, epsilon=0.02),
        camera=CameraLossConfig(weight=0.5, abs_weight=2.0, rel_weight=3.0,
                                rel_translation_weight=2.0, epsilon=0.05),
        temporal=TemporalLossConfig(weight=2.0, camera_weight=1.0, mano_weight=2.0,
                                    mask_weight=3.0, landmarks_weight=4.0),
        depth=DepthLossConfig(weight=2.5, confidence_alpha=0.3),
        rotation_clamp_eps=1e-6, min_scale_m=0.1)
