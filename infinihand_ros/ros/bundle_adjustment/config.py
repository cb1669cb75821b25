"""Settings of the bundle-adjustment node: its parameters, their specs and the BA settings.

The node's own parameters (``config/bundle_adjustment.yaml``, node
``infinihand_bundle_adjustment``) say which BA YAML to run (``config``: the ``ba`` section of
``config/ba.yaml`` layout; '' is the package's) and how keyframes are taken in; the pool,
solver, tracking and worker settings are that YAML's, so in-process BA and the node share one
file.
"""

from dataclasses import dataclass
from dataclasses import field
from pathlib import Path
from typing import Any, Final

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import load_ba_config
from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import config_from_dict
from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.ros.estimator.config import load_node_defaults
from infinihand_ros.ros.estimator.config import unflatten
from infinihand_ros.ros.estimator.parameter_specs import ParameterSpec

BA_NODE_NAME: Final = 'infinihand_bundle_adjustment'
BA_PARAMS_FILE: Final = 'bundle_adjustment.yaml'


@dataclass(frozen=True)
class KeyframeIntake:
    """How keyframe messages are taken in (parameters ``keyframes.*``).

    Attributes:
        max_pending: keyframes whose parts are still coming, held at most (oldest dropped).
        max_gap_s: a keyframe this much newer than the last one, or older, starts a new
            sequence (an estimator restarted: new world frame, empty pool).

    """

    max_pending: int = 8
    max_gap_s: float = 5.0

    def __post_init__(self) -> None:
        require_at_least('keyframes', 1, max_pending=self.max_pending)
        require_positive('keyframes', max_gap_s=self.max_gap_s)


@dataclass(frozen=True)
class BundleAdjustmentNodeConfig:
    """Everything the BA node is configured with (``config/bundle_adjustment.yaml``)."""

    config: str = ''
    world_frame_id: str = 'world'
    keyframes: KeyframeIntake = field(default_factory=KeyframeIntake)
    refined_path_length: int = 1000
    status_period_s: float = 1.0
    close_timeout_s: float = 5.0

    def __post_init__(self) -> None:
        if not self.world_frame_id:
            raise ConfigError('world_frame_id: must not be empty')
        require_at_least('node', 1, refined_path_length=self.refined_path_length)
        require_positive('node', status_period_s=self.status_period_s)
        require_at_least('node', 0.0, close_timeout_s=self.close_timeout_s)

    def ba_config(self) -> BAConfig:
        """Return the BA settings of the ``config`` file.

        Raises:
            ConfigError: naming ``config`` for a missing file, else naming the file's key.

        """
        if self.config and not Path(self.config).expanduser().is_file():
            raise ConfigError(f"config: {self.config!r} is not a file; give a BA YAML or '' "
                              "for the package's config/ba.yaml")
        return load_ba_config(Path(self.config).expanduser() if self.config else None)


BA_NODE_PARAMETER_SPECS: Final = {
    'config': ParameterSpec("BA YAML (config/ba.yaml layout, section ba); empty: the package's "
                            'config/ba.yaml.'),
    'world_frame_id': ParameterSpec('Frame id of the refined keyframe path and corrections.'),
    'keyframes.max_pending': ParameterSpec('Keyframes whose messages are still arriving, held '
                                           'at most.', 1, 10_000),
    'keyframes.max_gap_s': ParameterSpec('A keyframe this much newer than the last (or older) '
                                         'starts a new sequence, s.', 1e-3, 3600.0),
    'refined_path_length': ParameterSpec('Refined keyframe poses kept in the latched path.', 1,
                                         1_000_000),
    'status_period_s': ParameterSpec('Status period on /diagnostics and '
                                     'bundle_adjustment/status (the heartbeat), s.', 1e-3,
                                     3600.0),
    'close_timeout_s': ParameterSpec('On shutdown, a running BA call gets this long to finish, '
                                     's.', 0.0, 3600.0),
}


def load_ba_node_defaults(path: str | Path | None = None) -> dict[str, Any]:
    """Return the flat parameter defaults of ``config/bundle_adjustment.yaml`` (or ``path``)."""
    return load_node_defaults(Path(path) if path is not None else config_dir() / BA_PARAMS_FILE,
                              BA_NODE_NAME)


def ba_node_config_from_parameters(values: dict[str, Any]) -> BundleAdjustmentNodeConfig:
    """Build and check the config from flat parameter values (dotted names).

    Raises:
        ConfigError: naming the parameter for an unknown name, a wrong type or a bad value.

    """
    return config_from_dict(BundleAdjustmentNodeConfig, unflatten(values), BA_NODE_NAME)
