"""Settings of the estimator node: one frozen dataclass tree, the node's parameters flattened.

Parameter ``smoothing.beta`` is field ``beta`` of ``EstimatorConfig.smoothing``. The defaults
live in ``config/estimator.yaml`` (a ROS 2 params file); ``load_estimator_defaults`` reads them
and ``estimator_config_from_parameters`` builds and checks the tree from flat parameter values,
raising ``ConfigError`` that names the parameter.
"""

from dataclasses import dataclass
from dataclasses import field
from pathlib import Path
from typing import Any, Final

from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import config_from_dict
from infinihand_ros.core.config import read_yaml
from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.engine.config import MODES
from infinihand_ros.engine.output.config import IdentityConfig
from infinihand_ros.engine.output.config import ShapeConfig
from infinihand_ros.engine.output.config import SmoothingConfig

NODE_NAME: Final = 'infinihand_estimator'
PARAMS_FILE: Final = 'estimator.yaml'
ROS_PARAMETERS_KEY: Final = 'ros__parameters'
#: The params-file key that matches every node (ROS 2 wildcard).
ANY_NODE_KEY: Final = '/**'
CAMERA_MOTIONS: Final = ('estimate', 'static')
BA_MODES: Final = ('none', 'in_process', 'node')


def _require_choice(name: str, value: str, choices: tuple[str, ...]) -> None:
    """Raise ConfigError naming parameter ``name`` unless ``value`` is one of ``choices``."""
    if value not in choices:
        raise ConfigError(f'{name}: must be one of {list(choices)}, got {value!r}')


@dataclass(frozen=True)
class EngineSelection:
    """Which engine the node runs (parameters ``engine.*``; see ``config/estimator.yaml``)."""

    config: str = ''
    checkpoint: str = ''
    device: str = 'cpu'
    mode: str = 'per_frame'
    keyframe_interval: int = 1
    bundle_adjustment: str = 'none'

    def __post_init__(self) -> None:
        _require_choice('engine.mode', self.mode, MODES)
        _require_choice('engine.bundle_adjustment', self.bundle_adjustment, BA_MODES)
        require_at_least('engine', 1, keyframe_interval=self.keyframe_interval)


@dataclass(frozen=True)
class FrameIds:
    """Frame ids of the outputs (parameters ``frames.*``)."""

    world_frame_id: str = 'world'
    camera_frame_id: str = ''

    def __post_init__(self) -> None:
        if not self.world_frame_id:
            raise ConfigError('frames.world_frame_id: must not be empty')


@dataclass(frozen=True)
class FallbackIntrinsics:
    """Intrinsics used when no CameraInfo pairs (``camera.fallback.*``); fx = fy = 0: none.

    Attributes:
        fx: focal length along x, px (0.0 with ``fy`` 0.0: no fallback, the model's FoV).
        fy: focal length along y, px.
        cx: principal point x, px; 0.0 = the image centre.
        cy: principal point y, px; 0.0 = the image centre.

    """

    fx: float = 0.0
    fy: float = 0.0
    cx: float = 0.0
    cy: float = 0.0

    def __post_init__(self) -> None:
        if (self.fx > 0) != (self.fy > 0):
            raise ConfigError(f'camera.fallback: give both fx and fy (> 0) or '
                              f'neither (0.0), got fx={self.fx}, fy={self.fy}')
        require_at_least('camera.fallback', 0.0, fx=self.fx, fy=self.fy,
                         cx=self.cx, cy=self.cy)

    @property
    def enabled(self) -> bool:
        """Return whether fallback focal lengths are set."""
        return self.fx > 0


@dataclass(frozen=True)
class CameraSettings:
    """Camera motion and intrinsics (parameters ``camera.*``)."""

    motion: str = 'estimate'
    info_tolerance_s: float = 0.05
    info_wait_s: float = 0.2
    fallback: FallbackIntrinsics = field(default_factory=FallbackIntrinsics)

    def __post_init__(self) -> None:
        _require_choice('camera.motion', self.motion, CAMERA_MOTIONS)
        require_at_least('camera', 0.0, info_tolerance_s=self.info_tolerance_s,
                         info_wait_s=self.info_wait_s)


@dataclass(frozen=True)
class OutputSwitches:
    """Which outputs are published (parameters ``outputs.*``)."""

    camera_pose: bool = True
    camera_path: bool = True
    hands: bool = True
    markers: bool = True
    camera_info: bool = True
    path_length: int = 1000

    def __post_init__(self) -> None:
        require_at_least('outputs', 1, path_length=self.path_length)


@dataclass(frozen=True)
class DiagnosticsConfig:
    """Diagnostics period and statistics window (parameters ``diagnostics.*``)."""

    period_s: float = 1.0
    window_s: float = 5.0

    def __post_init__(self) -> None:
        require_positive('diagnostics', period_s=self.period_s,
                         window_s=self.window_s)


@dataclass(frozen=True)
class BANodeLinkConfig:
    """The link to the bundle-adjustment node (parameters ``ba_node.*``).

    Attributes:
        timeout_s: with ``engine.bundle_adjustment: node``, the BA node counts as lost (poses
            unrefined, WARN in diagnostics) when its status has not come for this long, s.

    """

    timeout_s: float = 3.0

    def __post_init__(self) -> None:
        require_positive('ba_node', timeout_s=self.timeout_s)


@dataclass(frozen=True)
class EstimatorConfig:
    """Everything the estimator node is configured with (``config/estimator.yaml``)."""

    engine: EngineSelection = field(default_factory=EngineSelection)
    frames: FrameIds = field(default_factory=FrameIds)
    camera: CameraSettings = field(default_factory=CameraSettings)
    outputs: OutputSwitches = field(default_factory=OutputSwitches)
    smoothing: SmoothingConfig = field(default_factory=SmoothingConfig)
    identity: IdentityConfig = field(default_factory=IdentityConfig)
    shape: ShapeConfig = field(default_factory=ShapeConfig)
    diagnostics: DiagnosticsConfig = field(default_factory=DiagnosticsConfig)
    ba_node: BANodeLinkConfig = field(default_factory=BANodeLinkConfig)
    bad_frame_log_period_s: float = 5.0

    def __post_init__(self) -> None:
        if not self.bad_frame_log_period_s > 0:
            raise ConfigError(f'bad_frame_log_period_s: must be positive, got '
                              f'{self.bad_frame_log_period_s!r}')


def flatten(tree: dict[str, Any], prefix: str = '') -> dict[str, Any]:
    """Return nested mappings as one mapping with dotted keys (ROS parameter names)."""
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            flat.update(flatten(value, f'{name}.'))
        else:
            flat[name] = value
    return flat


def unflatten(values: dict[str, Any]) -> dict[str, Any]:
    """Return dotted keys as nested mappings (the inverse of ``flatten``)."""
    tree: dict[str, Any] = {}
    for name, value in values.items():
        *parents, leaf = name.split('.')
        node = tree
        for parent in parents:
            node = node.setdefault(parent, {})
        node[leaf] = value
    return tree


def load_node_defaults(path: Path, node_name: str) -> dict[str, Any]:
    """Return the flat parameter defaults of ``node_name`` in the ROS params file ``path``.

    The section is ``<node_name>`` (also written ``/<node_name>``) or the wildcard ``/**``.

    Raises:
        ConfigError: for a missing file or one without such a ``ros__parameters`` section.

    """
    data = read_yaml(path)
    sections = data if isinstance(data, dict) else {}
    key = next((k for k in (node_name, f'/{node_name}', ANY_NODE_KEY) if k in sections), None)
    try:
        parameters = sections[key][ROS_PARAMETERS_KEY]
    except (KeyError, TypeError) as exc:
        raise ConfigError(f'{path}: no {node_name}.{ROS_PARAMETERS_KEY} (or '
                          f'{ANY_NODE_KEY}.{ROS_PARAMETERS_KEY}) section') from exc
    return flatten(parameters)


def load_estimator_defaults(path: str | Path | None = None) -> dict[str, Any]:
    """Return the flat parameter defaults of ``config/estimator.yaml`` (or ``path``)."""
    return load_node_defaults(Path(path) if path is not None else config_dir() / PARAMS_FILE,
                              NODE_NAME)


def estimator_config_from_parameters(values: dict[str, Any]) -> EstimatorConfig:
    """Build and check the config from flat parameter values (dotted names).

    Raises:
        ConfigError: naming the parameter for an unknown name, a wrong type or a bad value.

    """
    return config_from_dict(EstimatorConfig, unflatten(values), NODE_NAME)
