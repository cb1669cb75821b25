"""Settings of the bundle-adjustment node: its parameters (one dataclass tree) and BA settings.

The node's own parameters (node ``infinihand_bundle_adjustment``) say which BA YAML to run
(``config``: the ``ba`` section of ``config/ba.yaml`` layout; '' is the package's) and how
keyframes are taken in; the pool, solver, tracking and worker settings are that YAML's, so
in-process BA and the node share one file. The tree owns every parameter (``core.parameters``);
``config/bundle_adjustment.yaml`` is generated from it.
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import load_ba_config
from infinihand_ros.core.config import config_from_dict
from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.parameters import nested
from infinihand_ros.core.parameters import parameter
from infinihand_ros.core.parameters import unflatten

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

    max_pending: int = parameter(8, 'Keyframes whose messages are still arriving, held at '
                                 'most (oldest dropped).', 1, 10_000)
    max_gap_s: float = parameter(5.0, 'A keyframe this much newer than the last (or older) '
                                 'starts a new sequence, s.', 1e-3, 3600.0)

    def __post_init__(self) -> None:
        require_at_least('keyframes', 1, max_pending=self.max_pending)
        require_positive('keyframes', max_gap_s=self.max_gap_s)


@dataclass(frozen=True)
class BundleAdjustmentNodeConfig:
    """Everything the BA node is configured with (``config/bundle_adjustment.yaml``)."""

    config: str = parameter('', 'BA YAML (config/ba.yaml layout, section ba); empty: the '
                            "package's config/ba.yaml.")
    world_frame_id: str = parameter('world', 'Frame id of the refined keyframe path and the '
                                    'corrections.')
    keyframes: KeyframeIntake = nested(KeyframeIntake)
    refined_path_length: int = parameter(1000, 'Refined keyframe poses kept in '
                                         '~/refined_keyframe_path (latched).', 1, 1_000_000)
    status_period_s: float = parameter(1.0, 'Status period on /diagnostics and '
                                       'bundle_adjustment/status (the heartbeat), s.', 1e-3,
                                       3600.0)
    close_timeout_s: float = parameter(5.0, 'On shutdown, a running BA call gets this long to '
                                       'finish, s.', 0.0, 3600.0)

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


def ba_node_config_from_parameters(values: dict[str, Any]) -> BundleAdjustmentNodeConfig:
    """Build and check the config from flat parameter values (dotted names).

    Raises:
        ConfigError: naming the parameter for an unknown name, a wrong type or a bad value.

    """
    return config_from_dict(BundleAdjustmentNodeConfig, unflatten(values), BA_NODE_NAME)
