"""Build the engine's model: from checkpoints when configured, else seeded initial weights.

``engine.model`` may name a whole-model checkpoint (``checkpoint``: a directory or a bundled
model's name, ``model/io/bundled.py``) or the parts
``geometry_weights`` (a converted LingBot-Map / VGGT checkpoint) and ``crop_encoder_weights`` (a
converted WiLoR checkpoint); ``model/io/compose.py`` loads them together and seeds what none of
them provides with ``engine.model.seed``. The hand models come from ``engine.model.hand_model``
(the built-in skeleton, or real MANO from the user's files).
"""

import logging

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.mano.base import HandModel
from infinihand_ros.mano.hand_model import build_hand_model
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.model.infinihand_model import load_branch_configs
from infinihand_ros.model.io.bundled import resolve_checkpoint
from infinihand_ros.model.io.compose import load_composed_model

logger = logging.getLogger(__name__)


def build_model(config: EngineConfig,
                hand_models: tuple[HandModel, HandModel] | None = None) -> InfiniHandModel:
    """Build the model of ``config``, in eval mode on ``config.device``.

    With any checkpoint configured, the checkpoints' own configs define the model (a warning
    names each one that differs from ``engine.model.geometry`` / ``hand_branch``) and the
    loading report, by branch, is logged; otherwise the named configs with weights seeded by
    ``engine.model.seed``.

    Args:
        config: the engine config.
        hand_models: (left, right) hand models to use instead of ``engine.model.hand_model``.

    Raises:
        ConfigError: for a bad config name or file.
        CheckpointError: for a missing or non-matching checkpoint or MANO file.

    """
    selection = config.model
    geometry_config, hand_config = load_branch_configs(selection.geometry, selection.hand_branch)
    if hand_models is None:
        hand_models = (build_hand_model(selection.hand_model, LEFT),
                       build_hand_model(selection.hand_model, RIGHT))
    full = None if selection.checkpoint is None else str(resolve_checkpoint(selection.checkpoint))
    parts = {'full': full, 'geometry': selection.geometry_weights,
             'crop_encoder': selection.crop_encoder_weights}
    if all(path is None for path in parts.values()):
        model = build_infinihand_model(geometry_config, hand_config, seed=selection.seed,
                                       hand_models=hand_models)
        return model.eval().to(config.device)
    model, report = load_composed_model(**parts, geometry_config=geometry_config,
                                        hand_config=hand_config, seed=selection.seed,
                                        hand_models=hand_models, device=config.device)
    logger.info('model loaded:\n%s', report.describe())
    if model.geometry.config != geometry_config:
        logger.warning('checkpoint %s: its geometry config differs from engine.model.geometry '
                       '%r; the checkpoint wins', report.config_sources['geometry'],
                       selection.geometry)
    if model.hand_branch.config != hand_config:
        logger.warning('checkpoint %s: its hand-branch config differs from '
                       'engine.model.hand_branch %r; the checkpoint wins',
                       report.config_sources['hand_branch'], selection.hand_branch)
    return model
