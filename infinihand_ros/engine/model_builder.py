"""Build the engine's model: our checkpoint when one is configured, else seeded initial weights."""

import logging

from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.model.infinihand_checkpoint import load_infinihand_checkpoint
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.model.infinihand_model import load_branch_configs

logger = logging.getLogger(__name__)


def build_model(config: EngineConfig) -> InfiniHandModel:
    """Build the model of ``config``, in eval mode on its device.

    With ``config.checkpoint`` set, the checkpoint's own configs define the model (a warning
    names each one that differs from ``config.geometry``/``config.hand_branch``); otherwise the
    named configs with weights seeded by ``config.seed``.

    Raises:
        ConfigError: for a bad config name or file.
        CheckpointError: for a missing or non-matching checkpoint.

    """
    geometry_config, hand_config = load_branch_configs(config.geometry, config.hand_branch)
    if config.checkpoint is None:
        model = build_infinihand_model(geometry_config, hand_config, seed=config.seed)
        return model.eval().to(config.device)
    model, _ = load_infinihand_checkpoint(config.checkpoint, device=config.device)
    if model.geometry.config != geometry_config:
        logger.warning('checkpoint %s: its geometry config differs from engine.geometry %r; '
                       'the checkpoint wins', config.checkpoint, config.geometry)
    if model.hand_branch.config != hand_config:
        logger.warning('checkpoint %s: its hand-branch config differs from engine.hand_branch '
                       '%r; the checkpoint wins', config.checkpoint, config.hand_branch)
    return model
