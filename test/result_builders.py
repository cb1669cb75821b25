"""Builders of engine results and hands for tests (hand-set values)."""

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.datatypes import ManoParams
import numpy as np

#: A flat palm in the z = 0 plane: wrist at the origin, index MCP at (0.02, -0.08, 0), middle
#: MCP at (0, -0.09, 0); the other joints lie along -y (their values do not set the frame).
PALM_JOINTS = np.array([[0.0, -0.01 * j, 0.0] for j in range(21)])
PALM_JOINTS[5] = [0.02, -0.08, 0.0]
PALM_JOINTS[9] = [0.0, -0.09, 0.0]
#: The right hand's dex-retargeting wrist rotation of PALM_JOINTS, worked out by hand:
#: frame columns x = (0, 1, 0), y = (0, 0, 1), z = (1, 0, 0), times OPERATOR_TO_MANO[right].
PALM_RIGHT_WRIST_ROTATION = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])
INTRINSICS = Intrinsics(500.0, 500.0, 320.0, 240.0, 640, 480)


def make_hand(side: int, wrist_px: tuple[float, float] = (100.0, 100.0),
              confidence: float = 0.9, joints_world: np.ndarray | None = PALM_JOINTS,
              betas: np.ndarray | None = None) -> HandState:
    """Return a hand whose 2D wrist is at ``wrist_px`` (other 2D joints next to it)."""
    joints_2d = np.tile(np.array(wrist_px, dtype=np.float64), (21, 1))
    joints_2d[1:] += 5.0
    mano = ManoParams(np.zeros(3), np.zeros((15, 3)),
                      np.zeros(10) if betas is None else betas, np.zeros(3))
    joints = PALM_JOINTS if joints_world is None else joints_world
    return HandState(side, mano, np.array(joints), joints_2d, np.array([0.0, 0.0, 50.0, 50.0]),
                     confidence, mano_world=mano if joints_world is not None else None,
                     joints_world=None if joints_world is None else np.array(joints_world))


def make_result(stamp_ns: int, hands: tuple[HandState, ...] = (), index: int = 0,
                pose: CameraPose | None = None, version: int = 0) -> FrameResult:
    """Return an engine result with the given hands."""
    return FrameResult(timestamp_ns=stamp_ns, frame_index=index,
                       camera_pose=pose or CameraPose.identity(), intrinsics=INTRINSICS,
                       hands=hands, metric_scale=1.0, pose_version=version)
