"""Engine results to the fields of the node's output messages (plain numpy, no ROS types).

Frames (REP 103 / 105): the camera frame is the optical frame (x right, y down, z forward);
``camera_pose`` is ``T_world_cam``, the camera optical frame's pose in the world frame (the
first camera's, or the fixed camera's with ``camera.motion: static``). Per hand:

- ``landmarks_world``: the 21 joints (MediaPipe / OpenPose order) in the world frame, metres;
- ``wrist_pose``: the wrist joint's position in the world frame and, as orientation, the
  dex-retargeting wrist frame (``core.wrist_frame``: columns of ``wrist_rotation`` are its axes
  in the world frame);
- ``wrist_frame_landmarks``: the joints minus the wrist, expressed in that wrist frame (what
  dex-retargeting consumes; the wrist is at the origin).
"""

from dataclasses import dataclass

from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.core.wrist_frame import keypoints_in_wrist_frame
import numpy as np


@dataclass(frozen=True)
class PoseFields:
    """A geometry_msgs/Pose: position (3,) metres and orientation (x, y, z, w), w >= 0."""

    position: np.ndarray
    orientation_xyzw: np.ndarray

    @classmethod
    def from_rotation(cls, rotation: np.ndarray, position: np.ndarray) -> 'PoseFields':
        """Build from a (3, 3) rotation and a (3,) position."""
        return cls(np.asarray(position, dtype=np.float64).copy(),
                   geometry.matrix_to_quaternion_xyzw(np.asarray(rotation, dtype=np.float64)))

    @classmethod
    def from_camera_pose(cls, pose: CameraPose) -> 'PoseFields':
        """Build from a camera-to-world pose."""
        return cls.from_rotation(pose.rotation, pose.translation)


@dataclass(frozen=True)
class HandOutput:
    """What the node publishes for one seen hand.

    Attributes:
        side: 0 left, 1 right.
        confidence: presence score in [0, 1].
        landmarks_world: (21, 3) joints in the world frame, metres, MediaPipe order.
        wrist_frame_landmarks: (21, 3) root-relative joints in the wrist frame, metres.
        wrist_pose: the wrist frame's pose in the world frame.

    """

    side: int
    confidence: float
    landmarks_world: np.ndarray
    wrist_frame_landmarks: np.ndarray
    wrist_pose: PoseFields


@dataclass(frozen=True)
class FrameOutput:
    """Everything the node publishes for one frame.

    Attributes:
        stamp_ns: the source image's stamp (every output header carries it).
        frame_index: 0-based index in the engine's stream.
        camera_pose: ``T_world_cam`` of the optical camera frame.
        intrinsics: the intrinsics the engine used (given or predicted), source pixels.
        hands: per side (index 0 left, 1 right) the hand output, or None when not seen.
        metric_scale: metres per model unit applied to the trajectory.
        pose_version: the engine pose-track version ``camera_pose`` was computed with.
        keyframe: what goes to the bundle-adjustment node for this frame (None: nothing).

    """

    stamp_ns: int
    frame_index: int
    camera_pose: PoseFields
    intrinsics: Intrinsics
    hands: tuple[HandOutput | None, HandOutput | None]
    metric_scale: float
    pose_version: int
    keyframe: KeyframeInput | None = None


def hand_output(hand: HandState) -> HandOutput | None:
    """Return the outputs of a world-placed hand, or None when they cannot be formed.

    A hand without world joints, or whose palm joints are degenerate (no wrist frame), counts
    as not seen: the node publishes nothing stale and nothing made up.
    """
    if hand.joints_world is None:
        return None
    try:
        keypoints, rotation = keypoints_in_wrist_frame(hand.joints_world, hand.side)
    except InputError:
        return None
    return HandOutput(hand.side, float(hand.confidence), np.array(hand.joints_world),
                      keypoints, PoseFields.from_rotation(rotation, hand.joints_world[WRIST]))


def frame_output(result: FrameResult, hands: tuple[HandState, ...] | None = None
                 ) -> FrameOutput:
    """Return the outputs of an engine result.

    Args:
        result: the engine's result for one frame.
        hands: the hands to publish (after identity, shape and smoothing); the result's if None.

    """
    hands = result.hands if hands is None else hands
    by_side = {hand.side: hand_output(hand) for hand in hands}
    return FrameOutput(result.timestamp_ns, result.frame_index,
                       PoseFields.from_camera_pose(result.camera_pose), result.intrinsics,
                       tuple(by_side.get(side) for side in SIDES), result.metric_scale,
                       result.pose_version)
