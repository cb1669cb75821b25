"""Per-hand output fields of the estimator, from engine hands (plain numpy, no ROS types).

Frames (REP 103 / 105), per hand:

- ``landmarks_world``: the 21 joints (MediaPipe / OpenPose order) in the world frame, metres;
- ``wrist_pose``: the wrist joint's position in the world frame and, as orientation, the
  dex-retargeting wrist frame (``core.wrist_frame``: columns of ``wrist_rotation`` are its axes
  in the world frame);
- ``wrist_frame_landmarks``: the joints minus the wrist, expressed in that wrist frame (what
  dex-retargeting consumes; the wrist is at the origin).

The node (``ros/``) publishes them and the converter (``convert/``) draws markers of them.
"""

from dataclasses import dataclass

from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.errors import InputError
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

    @classmethod
    def from_camera_poses(cls, poses: list[CameraPose]) -> list['PoseFields']:
        """Build from camera-to-world poses, their rotations converted in one call."""
        if not poses:
            return []
        quaternions = geometry.matrix_to_quaternion_xyzw(np.stack([p.rotation for p in poses]))
        return [cls(np.asarray(pose.translation, dtype=np.float64).copy(), quaternion)
                for pose, quaternion in zip(poses, quaternions)]


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
