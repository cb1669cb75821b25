"""Settings of the estimator node: one frozen dataclass tree, the node's parameters flattened.

Parameter ``smoothing.beta`` is field ``beta`` of ``EstimatorConfig.smoothing``. The tree owns
every parameter: default, description, range and choices (``core.parameters``); the node
declares them from it, and ``config/estimator.yaml`` is generated from it
(``python -m infinihand_ros.tools.params_files --write``; a test fails when they differ).
``estimator_config_from_parameters`` builds and checks the tree from flat parameter values,
raising ``ConfigError`` that names the parameter. ``engine.*`` name the engine's settings
(profile, file, overrides); ``hands.*``, ``identity.*``, ``shape.*`` and ``smoothing.*`` are the
engine's own sections, declared from its dataclasses (``engine_setup.py``).
"""

from dataclasses import dataclass
from typing import Any, Final

from infinihand_ros.core.config import config_from_dict
from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.parameters import check_parameters
from infinihand_ros.core.parameters import nested
from infinihand_ros.core.parameters import parameter
from infinihand_ros.core.parameters import unflatten
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.output.config import IdentityConfig
from infinihand_ros.engine.output.config import ShapeConfig
from infinihand_ros.engine.output.config import SmoothingConfig
from infinihand_ros.engine.settings import DEFAULT_PROFILE
from infinihand_ros.engine.settings import PROFILES
from infinihand_ros.engine.settings import split_overrides

NODE_NAME: Final = 'infinihand_estimator'
PARAMS_FILE: Final = 'estimator.yaml'
BA_MODES: Final = ('none', 'in_process', 'node')
_BIG: Final = 1e9
_BIG_INT: Final = 2 ** 31 - 1


@dataclass(frozen=True)
class EngineSelection:
    """Which engine settings the node runs (parameters ``engine.*``)."""

    profile: str = parameter(DEFAULT_PROFILE, 'Engine settings profile (config/engine.yaml '
                             'lists what each changes): live (a moving camera), teleop (a fixed '
                             'camera: its pose is the world frame), offline, synthetic (our '
                             "synthetic data: the paper's hand branch).", choices=tuple(PROFILES))
    set: str = parameter(  # noqa: A003 (the parameter engine.set, as --set)
        '', 'Engine settings over the profile, as space-separated key=value '
        "pairs (dotted keys, YAML values), e.g. 'geometry_interval=1 "
        "device=cuda'.")
    config: str = parameter('', 'Engine settings file (config/engine.yaml layout, any subset of '
                            'its keys) applied between the profile and engine.set; empty: none.')
    checkpoint: str = parameter('', 'Whole-model checkpoint directory; empty: the engine '
                                "settings' (bundled) model.")
    bundle_adjustment: str = parameter(
        'none', 'Bundle adjustment: none (each pose measured by the per-frame camera tracker '
        "only; the best published poses on our test data); in_process (the engine's background "
        'worker process, config/ba.yaml; frames never wait for it); node (the '
        'bundle_adjustment node, config/bundle_adjustment.yaml).', choices=BA_MODES)

    def __post_init__(self) -> None:
        check_parameters(self, 'engine.')
        split_overrides(self.set, 'engine.set')


@dataclass(frozen=True)
class FrameIds:
    """Frame ids of the outputs (parameters ``frames.*``)."""

    world_frame_id: str = parameter('world', 'Frame id of every world-frame output.')
    camera_frame_id: str = parameter('', "Camera (optical) frame id; empty: the image header's "
                                     'frame id (an *_optical frame, REP 103).')
    left_wrist_frame_id: str = parameter('left_wrist', 'Frame id of the left wrist frame (the '
                                         'orientation of ~/hands/left/wrist_pose): frame of '
                                         '~/hands/left/wrist_frame_landmarks and its /tf child.')
    right_wrist_frame_id: str = parameter('right_wrist', 'Frame id of the right wrist frame, as '
                                          'left_wrist_frame_id for the right hand.')

    def __post_init__(self) -> None:
        ids = {'world_frame_id': self.world_frame_id,
               'left_wrist_frame_id': self.left_wrist_frame_id,
               'right_wrist_frame_id': self.right_wrist_frame_id}
        for name, frame_id in ids.items():
            if not frame_id:
                raise ConfigError(f'frames.{name}: must not be empty')
        if len(set(ids.values())) < len(ids):
            raise ConfigError(f'frames: the world and wrist frame ids must differ (a TF frame '
                              f'cannot be its own parent), got {ids}')

    def wrist_frame_id(self, side: int) -> str:
        """Return the frame id of a side's wrist frame (0 left, 1 right)."""
        return (self.left_wrist_frame_id, self.right_wrist_frame_id)[side]


@dataclass(frozen=True)
class FallbackIntrinsics:
    """Intrinsics used when no CameraInfo pairs (``camera.fallback.*``); fx = fy = 0: none."""

    fx: float = parameter(0.0, 'Fallback focal length x when no CameraInfo pairs, px; 0.0 '
                          "(with fy 0.0): the model's field of view.", 0.0, _BIG)
    fy: float = parameter(0.0, 'Fallback focal length y, px; 0.0: none.', 0.0, _BIG)
    cx: float = parameter(0.0, 'Fallback principal point x, px; 0.0: the image centre.', 0.0,
                          _BIG)
    cy: float = parameter(0.0, 'Fallback principal point y, px; 0.0: the image centre.', 0.0,
                          _BIG)

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
    """The camera's stamps and intrinsics (parameters ``camera.*``).

    Its motion is the engine's ``camera_motion`` (profile ``teleop``: a fixed camera).
    """

    info_tolerance_s: float = parameter(0.05, 'A CameraInfo pairs with an image whose stamp is '
                                        'at most this far from its own, s.', 0.0, 3600.0)
    info_wait_s: float = parameter(0.2, 'Once CameraInfos arrive, an image waits at most this '
                                   'long for its own (it may come just after it), s.', 0.0, 10.0)
    fallback: FallbackIntrinsics = nested(FallbackIntrinsics)

    def __post_init__(self) -> None:
        check_parameters(self, 'camera.')
        require_at_least('camera', 0.0, info_tolerance_s=self.info_tolerance_s,
                         info_wait_s=self.info_wait_s)


@dataclass(frozen=True)
class OutputSwitches:
    """Which outputs are published (parameters ``outputs.*``)."""

    camera_pose: bool = parameter(True, 'Publish ~/camera_pose.')
    camera_path: bool = parameter(True, 'Publish ~/camera_path (latched).')
    hands: bool = parameter(True, 'Publish ~/hands/{left,right}/{wrist_pose,landmarks,'
                            'wrist_frame_landmarks}.')
    markers: bool = parameter(True, 'Publish ~/hands/markers.')
    camera_info: bool = parameter(True, 'Publish ~/camera_info (the intrinsics used).')
    hand_frame: bool = parameter(True, 'Publish ~/hands (infinihand_msgs/HandFrame: the camera '
                                 'pose and both hands of each image, as the estimates bag '
                                 'holds them).')
    path_length: int = parameter(1000, 'Poses kept in ~/camera_path (oldest dropped first).', 1,
                                 1_000_000)
    path_period_s: float = parameter(1.0, 'Publish ~/camera_path and its marker once per this '
                                     'many seconds of image time, a refined trajectory (new '
                                     'scale, BA) re-read just before (a long path takes tens of '
                                     'ms to re-read and send); 0.0: with every frame.', 0.0,
                                     3600.0)

    def __post_init__(self) -> None:
        require_at_least('outputs', 1, path_length=self.path_length)
        require_at_least('outputs', 0.0, path_period_s=self.path_period_s)


@dataclass(frozen=True)
class TFSettings:
    """Transforms broadcast on /tf with each frame (parameters ``tf.*``)."""

    enabled: bool = parameter(True, 'Broadcast /tf (tf2_msgs/TFMessage, stamped with the image): '
                              'world -> camera frame and world -> the wrist frame of each hand '
                              'published.')
    camera: bool = parameter(True, 'Include world -> camera frame (the camera pose; with '
                             'engine profile teleop once on /tf_static); false when another '
                             'node gives the camera frame its parent (a URDF): a TF frame has '
                             'one parent.')


@dataclass(frozen=True)
class DiagnosticsConfig:
    """Diagnostics period and statistics window (parameters ``diagnostics.*``)."""

    period_s: float = parameter(1.0, '/diagnostics publishing period, s.', 1e-3, 3600.0)
    window_s: float = parameter(5.0, 'Rates and latency percentiles cover this much recent '
                                'time, s.', 1e-3, 3600.0)

    def __post_init__(self) -> None:
        require_positive('diagnostics', period_s=self.period_s,
                         window_s=self.window_s)


@dataclass(frozen=True)
class BANodeLinkConfig:
    """The link to the bundle-adjustment node (parameters ``ba_node.*``)."""

    timeout_s: float = parameter(3.0, 'With engine.bundle_adjustment node: the BA node counts '
                                 'as lost (poses go on unrefined) when its status has not come '
                                 'for this long, s.', 1e-3, 3600.0)

    def __post_init__(self) -> None:
        require_positive('ba_node', timeout_s=self.timeout_s)


@dataclass(frozen=True)
class EstimatorConfig:
    """Everything the estimator node is configured with (its parameters)."""

    engine: EngineSelection = nested(EngineSelection)
    frames: FrameIds = nested(FrameIds)
    camera: CameraSettings = nested(CameraSettings)
    outputs: OutputSwitches = nested(OutputSwitches)
    tf: TFSettings = nested(TFSettings)
    hands: HandsConfig = nested(HandsConfig)
    smoothing: SmoothingConfig = nested(SmoothingConfig)
    identity: IdentityConfig = nested(IdentityConfig)
    shape: ShapeConfig = nested(ShapeConfig)
    diagnostics: DiagnosticsConfig = nested(DiagnosticsConfig)
    ba_node: BANodeLinkConfig = nested(BANodeLinkConfig)
    bad_frame_log_period_s: float = parameter(5.0, 'Throttle of the bad-frame and the '
                                              'out-of-order-frame warnings, s.', 1e-3, 3600.0)

    def __post_init__(self) -> None:
        if not self.bad_frame_log_period_s > 0:
            raise ConfigError(f'bad_frame_log_period_s: must be positive, got '
                              f'{self.bad_frame_log_period_s!r}')


def estimator_config_from_parameters(values: dict[str, Any]) -> EstimatorConfig:
    """Build and check the config from flat parameter values (dotted names).

    Raises:
        ConfigError: naming the parameter for an unknown name, a wrong type or a bad value.

    """
    return config_from_dict(EstimatorConfig, unflatten(values), NODE_NAME)
