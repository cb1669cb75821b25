"""The whole InfiniHand model: the geometry branch and the hand branch, built from their configs.

``InfiniHandModel`` only holds the two branches (state-dict prefixes ``geometry.`` and
``hand_branch.``); the engine runs them. ``build_infinihand_model`` makes a seeded model without
touching the caller's random state, and ``load_branch_configs`` resolves config names or paths.
"""

from pathlib import Path
from typing import Final

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.mano.base import HandModel
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.config import named_config_path
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.hand.hand_branch import HandBranch
import torch
from torch import nn

#: State-dict prefixes of the two branches.
GEOMETRY_PREFIX: Final = 'geometry.'
HAND_BRANCH_PREFIX: Final = 'hand_branch.'
#: State-dict prefix of the hand models' tensors (MANO data when real MANO is used): never saved.
HAND_MODELS_PREFIX: Final = 'hand_branch.hand_models.'


class InfiniHandModel(nn.Module):
    """Geometry branch (camera, depth, hand masks, patch features) + hand branch (MANO hands)."""

    def __init__(self, geometry: GeometryModel, hand_branch: HandBranch) -> None:
        """Hold the two branches; the hand branch reads the geometry branch's patch features.

        Raises:
            ConfigError: when the hand branch expects features of another width.

        """
        super().__init__()
        feature_dim = geometry.config.aggregator.output_dim
        if hand_branch.feature_dim != feature_dim:
            raise ConfigError(f'hand branch built for {hand_branch.feature_dim}-d features, but '
                              f'the geometry branch gives {feature_dim}-d; build it with '
                              'feature_dim=geometry.config.aggregator.output_dim')
        self.geometry = geometry
        self.hand_branch = hand_branch


def build_infinihand_model(geometry_config: GeometryConfig, hand_config: HandBranchConfig,
                           seed: int = 0,
                           hand_models: tuple[HandModel, HandModel] | None = None
                           ) -> InfiniHandModel:
    """Return a model with seeded initial weights, in train mode on the CPU.

    Args:
        geometry_config: geometry-branch sizes.
        hand_config: hand-branch sizes.
        seed: seed of the weight initialisation (the caller's random state is restored).
        hand_models: (left, right) hand models; the built-in skeletons if None.

    """
    generator_state = torch.random.get_rng_state()
    torch.manual_seed(seed)
    try:
        geometry = GeometryModel(geometry_config)
        hand_branch = HandBranch(hand_config, geometry_config.aggregator.output_dim,
                                 hand_models=hand_models)
    finally:
        torch.random.set_rng_state(generator_state)
    return InfiniHandModel(geometry, hand_branch)


def load_branch_configs(geometry: str | Path,
                        hand_branch: str | Path) -> tuple[GeometryConfig, HandBranchConfig]:
    """Load the two branch configs, each a name ('tiny', 'paper') or a YAML path.

    Raises:
        ConfigError: for an unknown name, a missing file or a bad value.

    """
    text = str(geometry)
    geometry_path = Path(text) if text.endswith(('.yaml', '.yml')) else named_config_path(text)
    return load_geometry_config(geometry_path), load_hand_branch_config(hand_branch)
