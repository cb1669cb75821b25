"""The node's engine settings: its profile, settings file and parameters resolved into one.

``engine.profile`` names the profile (``live`` by default), ``engine.config`` a settings file
over it, and ``engine.set`` overrides applied last. Between the file and ``engine.set`` come the
node's own: ``engine.checkpoint``, ``engine.bundle_adjustment`` and the engine sections the node
declares as parameters (``hands.*``, ``identity.*``, ``shape.*``, ``smoothing.*``), each where it
differs from the engine's default, so a parameter left alone keeps the profile's value. Errors
name the parameter.
"""

from pathlib import Path
from typing import Any, Final

from infinihand_ros.core.config import config_to_dict
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.settings import build_engine_config
from infinihand_ros.engine.settings import checkpoint_overrides
from infinihand_ros.engine.settings import split_overrides
from infinihand_ros.ros.estimator.config import EstimatorConfig

#: ``ba.worker.when_behind`` of the node's in-process BA: never wait for room in the queue.
LIVE_WHEN_BEHIND: Final = 'drop'
#: Node parameter sections that are engine sections: parameter prefix -> engine key.
ENGINE_SECTIONS: Final = {'hands': 'hands', 'identity': 'output.identity',
                          'shape': 'output.shape', 'smoothing': 'output.smoothing'}


def node_overrides(config: EstimatorConfig) -> dict[str, Any]:
    """Return the engine settings the node's parameters set (``engine.set`` excluded).

    ``bundle_adjustment: in_process`` keeps the settings file's BA, else the package's
    ``config/ba.yaml``, with ``worker.when_behind: drop`` whatever they say: a live node never
    waits for BA (a selection that finds the queue full replaces the oldest waiting one).
    ``none`` and ``node`` (BA in the bundle_adjustment node, through the engine's ``RemoteBA``
    backend that the node passes to the engine) run no BA worker in the engine.

    Raises:
        ConfigError: naming ``engine.checkpoint`` when it is not a directory.

    """
    selection = config.engine
    overrides: dict[str, Any] = {}
    if selection.checkpoint:
        checkpoint = Path(selection.checkpoint).expanduser()
        if not checkpoint.is_dir():
            raise ConfigError(f'engine.checkpoint: {selection.checkpoint!r} is not a checkpoint '
                              "directory; give one or '' for the engine settings' model")
        overrides.update(checkpoint_overrides(str(checkpoint)))
    defaults = EngineConfig()
    for prefix, key in ENGINE_SECTIONS.items():
        given = config_to_dict(getattr(config, prefix))
        default = config_to_dict(_section(defaults, key))
        overrides.update({f'{key}.{name}': value for name, value in given.items()
                          if value != default[name]})
    return overrides


def engine_config_for(config: EstimatorConfig) -> EngineConfig:
    """Return the engine settings the node's parameters describe.

    Raises:
        ConfigError: naming the parameter (``engine.config``, ``engine.checkpoint``,
            ``engine.set``) or the settings file's key.

    """
    selection = config.engine
    if selection.config and not Path(selection.config).expanduser().is_file():
        raise ConfigError(f'engine.config: {selection.config!r} is not a file; give an engine '
                          "settings YAML or '' for none")
    overrides = node_overrides(config)
    if selection.bundle_adjustment == 'in_process':  # the file's or profile's BA, else ba.yaml
        overrides['bundle_adjustment'] = True
        overrides['bundle_adjustment.worker.when_behind'] = LIVE_WHEN_BEHIND
    else:
        overrides['bundle_adjustment'] = None
    overrides.update(split_overrides(selection.set, 'engine.set'))
    try:
        return build_engine_config(
            selection.profile, overrides,
            Path(selection.config).expanduser() if selection.config else None)
    except ConfigError as exc:
        raise ConfigError(f'engine parameters: {exc}') from exc


def _section(config: Any, key: str) -> Any:
    """Return the nested section ``key`` (dotted) of a config."""
    for part in key.split('.'):
        config = getattr(config, part)
    return config
