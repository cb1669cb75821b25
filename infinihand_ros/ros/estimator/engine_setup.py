"""The node's engine configuration: the engine YAML with the node's parameters applied.

The YAML is ``config/engine.yaml`` unless ``engine.config`` names another. The ``engine.*``
parameters select the mode, the keyframe and geometry intervals, device, checkpoint and BA;
``camera.motion`` is the engine's ``camera_motion``, ``camera.restart_after_s`` its
``restart_after_s`` (the stream policy), ``hands.*`` its hand source (they replace the file's
``hands`` section) and ``identity.*``, ``shape.*`` and ``smoothing.*`` its output stage (they
replace the file's ``output`` section). Errors name the parameter.
"""

from dataclasses import replace
from pathlib import Path
from typing import Final

from infinihand_ros.ba.config import load_ba_config
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.config import check_device
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.config import load_engine_config
from infinihand_ros.engine.output.config import OutputConfig
from infinihand_ros.ros.estimator.config import EstimatorConfig

#: ``ba.worker.when_behind`` of the node's in-process BA: never wait for room in the queue.
LIVE_WHEN_BEHIND: Final = 'drop'


def engine_config_for(config: EstimatorConfig) -> EngineConfig:
    """Return the engine config the node's parameters describe.

    ``bundle_adjustment: in_process`` (the default) keeps the engine file's BA settings, or uses
    the package's ``config/ba.yaml`` when that file has none, with ``worker.when_behind: drop``
    whatever the file says: a live node never waits for BA (a selection that finds the queue
    full replaces the oldest waiting one). ``none`` and ``node`` (BA in the bundle_adjustment
    node, through the engine's ``RemoteBA`` backend that the node passes to the engine) run no
    BA worker in the engine.

    Raises:
        ConfigError: naming the parameter (``engine.config``, ``engine.checkpoint``,
            ``engine.device``) or the engine file's key.

    """
    selection = config.engine
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
        ba = replace(ba, worker=replace(ba.worker, when_behind=LIVE_WHEN_BEHIND))
    output = OutputConfig(config.identity, config.shape, config.smoothing)
    return replace(base, mode=selection.mode, keyframe_interval=selection.keyframe_interval,
                   geometry_interval=selection.geometry_interval,
                   geometry_lag=selection.geometry_lag, device=selection.device,
                   model=model, bundle_adjustment=ba,
                   camera_motion=config.camera.motion, output=output, hands=config.hands,
                   restart_after_s=config.camera.restart_after_s)
