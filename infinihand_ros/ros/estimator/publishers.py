"""The estimator's publishers and how one engine result is published on them.

Every header stamp is the source image's stamp. World-frame outputs carry
``frames.world_frame_id``; ``~/camera_info`` the camera's optical frame id; the wrist-frame
landmarks the frame ``<world>/<side>_wrist`` they are expressed in (the wrist pose gives it).
Per hand, the fields are ``core.output_fields.HandOutput``; a hand that is not seen (or
whose wrist frame cannot be formed) gets empty landmark arrays and DELETE markers, and no wrist
pose.
"""

from geometry_msgs.msg import PoseArray
from geometry_msgs.msg import PoseStamped
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.output_fields import hand_output
from infinihand_ros.core.output_fields import HandOutput
from infinihand_ros.core.output_fields import PoseFields
from infinihand_ros.ros import msg_builders
from infinihand_ros.ros.estimator.config import OutputSwitches
from infinihand_ros.vis.markers import hand_markers
from infinihand_ros.vis.markers import MarkerSpec
from infinihand_ros.vis.markers import path_marker
from nav_msgs.msg import Path
import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy
from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy
from sensor_msgs.msg import CameraInfo
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

#: Outputs: reliable, the last few kept for late readers of a slow link.
OUTPUT_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
#: Latched outputs (the path, the joint names): the last message reaches late subscribers.
LATCHED_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)


def wrist_frame_id(world_frame_id: str, side: int) -> str:
    """Return the frame id of a side's wrist frame."""
    return f'{world_frame_id}/{SIDE_NAMES[side]}_wrist'


class OutputPublishers:
    """Creates the node's output publishers and publishes frame outputs on them."""

    def __init__(self, node: Node, switches: OutputSwitches, world_frame_id: str) -> None:
        """Create the publishers the switches ask for (and the latched joint names)."""
        self.switches = switches
        self.world = world_frame_id
        create = node.create_publisher
        self.camera_pose = create(PoseStamped, '~/camera_pose', OUTPUT_QOS)
        self.camera_path = create(Path, '~/camera_path', LATCHED_QOS)
        self.camera_info = create(CameraInfo, '~/camera_info', OUTPUT_QOS)
        self.markers = create(MarkerArray, '~/hands/markers', OUTPUT_QOS)
        self.hands = {
            side: {'wrist_pose': create(PoseStamped, f'~/hands/{name}/wrist_pose', OUTPUT_QOS),
                   'landmarks': create(PoseArray, f'~/hands/{name}/landmarks', OUTPUT_QOS),
                   'wrist_frame_landmarks': create(
                       PoseArray, f'~/hands/{name}/wrist_frame_landmarks', OUTPUT_QOS)}
            for side, name in zip(SIDES, SIDE_NAMES)}
        self.joint_names = create(String, '~/hands/joint_names', LATCHED_QOS)
        self.joint_names.publish(msg_builders.joint_names_msg())

    def publish(self, result: FrameResult, camera_frame_id: str,
                path: list[tuple[int, PoseFields]] | None) -> None:
        """Publish one frame's outputs.

        Args:
            result: the engine's result of the frame.
            camera_frame_id: frame id of ``~/camera_info``.
            path: the camera path's (stamp, pose) pairs up to this frame, to publish with it
                (None: the path is not published with this frame).

        """
        stamp, switches = result.timestamp_ns, self.switches
        hands = {side: None if result.hand(side) is None else hand_output(result.hand(side))
                 for side in SIDES}
        if switches.camera_pose:
            self.camera_pose.publish(msg_builders.pose_stamped_msg(
                stamp, self.world, PoseFields.from_camera_pose(result.camera_pose)))
        if switches.camera_path and path is not None:
            self.camera_path.publish(msg_builders.path_msg(stamp, self.world, path))
        if switches.camera_info:
            self.camera_info.publish(msg_builders.camera_info_msg(stamp, camera_frame_id,
                                                                  result.intrinsics))
        if switches.hands:
            self._publish_hands(stamp, hands)
        if switches.markers:
            specs: list[MarkerSpec] = []
            for side in SIDES:
                specs += hand_markers(side, hands[side])
            if path is not None:
                specs.append(path_marker(np.array([pose.position for _, pose in path])))
            self.markers.publish(msg_builders.marker_array_msg(stamp, self.world, specs))

    def _publish_hands(self, stamp: int, hands: dict[int, HandOutput | None]) -> None:
        """Publish each side's wrist pose and landmark arrays (empty when not seen)."""
        for side in SIDES:
            hand, publishers = hands[side], self.hands[side]
            if hand is not None:
                publishers['wrist_pose'].publish(msg_builders.pose_stamped_msg(
                    stamp, self.world, hand.wrist_pose))
            publishers['landmarks'].publish(msg_builders.pose_array_msg(
                stamp, self.world, None if hand is None else hand.landmarks_world))
            publishers['wrist_frame_landmarks'].publish(msg_builders.pose_array_msg(
                stamp, wrist_frame_id(self.world, side),
                None if hand is None else hand.wrist_frame_landmarks))
