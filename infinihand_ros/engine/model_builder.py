"""The whole InfiniHand model: the geometry branch and the hand branch, built from configs."""

from pathlib import Path

from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.config import named_config_path
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.hand.hand_branch import HandBranch
import torch
from torch import nn


class InfiniHandModel(nn.Module):
    """Geometry branch (camera, depth, hand masks, patch features) + hand branch (MANO hands)."""

    def __init__(self, geometry: GeometryModel, hand_branch: HandBranch) -> None:
        """Hold the two branches; the hand branch reads the geometry branch's patch features."""
        super().__init__()
        self.geometry = geometry
        self.hand_branch = hand_branch


def _geometry_config_path(name_or_path: str) -> Path:
    """Return the YAML path of a geometry config name ('tiny', 'paper') or path."""
    return Path(name_or_path) if name_or_path.endswith(('.yaml', '.yml')) else \
        named_config_path(name_or_path)


def build_model(config: EngineConfig) -> InfiniHandModel:
    """Build the model of ``config`` (seeded initial weights), in eval mode on its device.

    Trained weights do not exist yet; loading them comes with the training issue.
    """
    geometry_config = load_geometry_config(_geometry_config_path(config.geometry))
    hand_config = load_hand_branch_config(config.hand_branch)
    generator_state = torch.random.get_rng_state()
    torch.manual_seed(config.seed)
    try:
        geometry = GeometryModel(geometry_config)
        hand_branch = HandBranch(hand_config, feature_dim=geometry_config.aggregator.output_dim)
    finally:
        torch.random.set_rng_state(generator_state)
    return InfiniHandModel(geometry, hand_branch).eval().to(config.device)
