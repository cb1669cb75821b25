"""The node's engine configuration: the engine YAML with the ``engine.*`` parameters applied.

The YAML is ``config/engine.yaml`` unless ``engine.config`` names another; errors name the
parameter.
"""

from dataclasses import replace
from pathlib import Path

from infinihand_ros.ba.config import load_ba_config
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.config import check_device
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.config import load_engine_config
from infinihand_ros.ros.estimator.config import EngineSelection


def engine_config_for(selection: EngineSelection) -> EngineConfig:
    """Return the engine config the node's ``engine.*`` parameters describe.

    ``bundle_adjustment: in_process`` keeps the engine file's BA settings, or uses the
    package's ``config/ba.yaml`` when that file has none; ``none`` and ``node`` (BA in the
    bundle_adjustment node, corrections applied by the node's pipeline) run no BA in the engine.

    Raises:
        ConfigError: naming the parameter (``engine.config``, ``engine.checkpoint``,
            ``engine.device``) or the engine file's key.

    """
    if selection.config and not Path(selection.config).expanduser().is_file():
        raise ConfigError(f'engine.config: {selection.config!r} is not a file; give an engine '
                          "YAML or '' for the package's config/engine.yaml")
    base = load_engine_config(Path(selection.config).expanduser() if selection.config else None)
    model = base.model
    if selection.checkpoint:
        if not Path(selection.checkpoint).expanduser().is_dir():
            raise ConfigError(f'engine.checkpoint: {selection.checkpoint!r} is not a checkpoint '
                              "directory; give one or '' for the engine config's model")
        model = replace(model, checkpoint=str(Path(selection.checkpoint).expanduser()),
                        geometry_weights=None, crop_encoder_weights=None)
    check_device(selection.device, 'engine.device')
    ba = None
    if selection.bundle_adjustment == 'in_process':
        ba = base.bundle_adjustment or load_ba_config()
    return replace(base, mode=selection.mode, keyframe_interval=selection.keyframe_interval,
                   device=selection.device, model=model, bundle_adjustment=ba)
