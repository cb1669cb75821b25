"""The estimator's publishers and how one engine result is published on them.

Every header stamp is the source image's stamp. World-frame outputs carry
``frames.world_frame_id``; ``~/camera_info`` the camera's optical frame id; the wrist-frame
landmarks the side's ``frames.*_wrist_frame_id``, the frame they are expressed in (the wrist
pose gives it). Per hand, the fields are ``core.output_fields.HandOutput``; a hand that is not
seen (or whose wrist frame cannot be formed) gets empty landmark arrays and DELETE markers, and
no wrist pose.

``~/hands`` (``outputs.hand_frame``): one ``infinihand_msgs/HandFrame`` per image, both hands
and the camera, made by ``bag.messages.frame_result_to_msg`` as the converter's estimates bag
is, and published serialized (the bag typestore's definition is the generated type's).

``/tf`` (``tf.*``), as ``tf2_ros.TransformBroadcaster`` publishes it (its topic and QoS): one
``tf2_msgs/TFMessage`` per frame holding world -> camera frame (the camera pose,
camera-to-world) and world -> wrist frame of each hand with a wrist pose. With a fixed camera
(``camera_motion: static``, profile ``teleop``) world -> camera never changes: it goes once to
``/tf_static`` (latched, as ``tf2_ros.StaticTransformBroadcaster`` sends it) instead. ``make``
builds ``tf2_msgs`` and ``infinihand_msgs`` where no ROS 2 install provides them; an output whose
type cannot be imported stops the node at start-up with a ``ConfigError`` saying so.
"""

import importlib
from typing import Any, Final

from geometry_msgs.msg import PoseArray
from geometry_msgs.msg import PoseStamped
from geometry_msgs.msg import TransformStamped
from infinihand_ros.bag.messages import frame_result_to_msg
from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.bag.typestore import HAND_FRAME_MSG
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.output_fields import hand_output
from infinihand_ros.core.output_fields import HandOutput
from infinihand_ros.core.output_fields import PoseFields
from infinihand_ros.ros import msg_builders
from infinihand_ros.ros.estimator.config import FrameIds
from infinihand_ros.ros.estimator.config import OutputSwitches
from infinihand_ros.ros.estimator.config import TFSettings
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

#: /tf as ``tf2_ros.TransformBroadcaster`` publishes it (its QoS: reliable, volatile, 100 deep).
TF_TOPIC: Final = '/tf'
TF_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
#: /tf_static as ``tf2_ros.StaticTransformBroadcaster`` publishes it (reliable, latched).
TF_STATIC_TOPIC: Final = '/tf_static'
TF_STATIC_QOS = LATCHED_QOS
TF_TYPE: Final = ('tf2_msgs.msg', 'TFMessage')
HAND_FRAME_TOPIC: Final = '~/hands'
HAND_FRAME_TYPE: Final = ('infinihand_msgs.msg', 'HandFrame')


def message_type(module_and_class: tuple[str, str], switch: str | None = None) -> Any:
    """Return a generated message class.

    Raises:
        ConfigError: when its package cannot be imported, saying how to build it (and naming
            the parameter ``switch`` that turns its output off).

    """
    module, name = module_and_class
    try:
        return getattr(importlib.import_module(module), name)
    except ImportError as exc:
        package = module.split('.')[0]
        off = '' if switch is None else f', or set {switch}:=false'
        raise ConfigError(
            f'{package} cannot be imported ({exc}): build the interface packages with make (or '
            f'colcon build --base-paths . $(scripts/interface_packages.sh)) and source '
            f'scripts/env.sh{off}') from exc


def frame_transforms(result: FrameResult, hands: dict[int, HandOutput | None],
                     frames: FrameIds, camera_frame_id: str | None) -> list[TransformStamped]:
    """Return the /tf transforms of one frame, stamped with its image.

    Args:
        result: the engine's result of the frame (stamp, camera pose).
        hands: each side's published outputs (None: not seen, no transform).
        frames: the world and wrist frame ids.
        camera_frame_id: the camera's optical frame id; None (or the world frame's id, as for
            a static camera whose frame is the world) leaves world -> camera out.

    Returns:
        world -> camera frame (camera-to-world pose), then world -> wrist frame per seen hand
        (the wrist pose: the joint's position, the wrist frame's axes).

    """
    stamp, world = result.timestamp_ns, frames.world_frame_id
    transforms = []
    if camera_frame_id is not None and camera_frame_id != world:
        transforms.append(msg_builders.transform_stamped_msg(
            stamp, world, camera_frame_id, PoseFields.from_camera_pose(result.camera_pose)))
    for side in SIDES:
        hand = hands[side]
        if hand is not None:
            transforms.append(msg_builders.transform_stamped_msg(
                stamp, world, frames.wrist_frame_id(side), hand.wrist_pose))
    return transforms


class OutputPublishers:
    """Creates the node's output publishers and publishes frame outputs on them."""

    def __init__(self, node: Node, switches: OutputSwitches, frames: FrameIds,
                 tf: TFSettings, static_camera: bool = False) -> None:
        """Create the publishers the switches ask for (and the latched joint names).

        Args:
            node: the node that owns the publishers.
            switches: which outputs to publish.
            frames: the world and wrist frame ids.
            tf: what to broadcast on /tf.
            static_camera: the camera never moves (``camera_motion: static``, profile
                ``teleop``): world -> camera goes once to /tf_static instead of /tf with every
                frame.

        Raises:
            ConfigError: when ``~/hands`` or /tf is asked for and its message package cannot
                be imported.

        """
        self.switches = switches
        self.frames = frames
        self.world = frames.world_frame_id
        self.tf = tf
        self.static_camera = static_camera
        # The last path's pose messages by stamp, with the pose each was built from.
        self._path_poses: dict[int, tuple[PoseFields, PoseStamped]] = {}
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
        self._typestore = build_typestore() if switches.hand_frame else None
        self.hand_frame = (create(message_type(HAND_FRAME_TYPE, 'outputs.hand_frame'),
                                  HAND_FRAME_TOPIC, OUTPUT_QOS) if switches.hand_frame else None)
        self._tf_message = message_type(TF_TYPE, 'tf.enabled') if tf.enabled else None
        self.transforms = (create(self._tf_message, TF_TOPIC, TF_QOS) if tf.enabled
                           else None)
        self.static_transforms = (create(self._tf_message, TF_STATIC_TOPIC, TF_STATIC_QOS)
                                  if tf.enabled and tf.camera and static_camera else None)
        self._static_camera_frame: str | None = None  # the camera frame sent on /tf_static

    def publish(self, result: FrameResult, camera_frame_id: str,
                path: list[tuple[int, PoseFields]] | None) -> None:
        """Publish one frame's outputs.

        Args:
            result: the engine's result of the frame.
            camera_frame_id: frame id of ``~/camera_info`` and the camera's /tf frame.
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
            self.camera_path.publish(self._path_msg(stamp, path))
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
        if self.transforms is not None:  # first, so a consumer of ~/hands finds its wrist
            self._publish_transforms(result, hands, camera_frame_id)
        if self.hand_frame is not None:
            self.hand_frame.publish(bytes(self._typestore.serialize_cdr(
                frame_result_to_msg(self._typestore, result, self.world), HAND_FRAME_MSG)))

    def _publish_transforms(self, result: FrameResult, hands: dict[int, HandOutput | None],
                            camera_frame_id: str) -> None:
        """Broadcast the frame's transforms; a fixed camera's once on /tf_static."""
        moving_camera = camera_frame_id if self.tf.camera and not self.static_camera else None
        transforms = frame_transforms(result, hands, self.frames, moving_camera)
        if transforms:
            self.transforms.publish(self._tf_message(transforms=transforms))
        if self.static_transforms is not None and camera_frame_id != self._static_camera_frame:
            static = frame_transforms(result, dict.fromkeys(SIDES), self.frames,
                                      camera_frame_id)
            if static:
                self.static_transforms.publish(self._tf_message(transforms=static))
            self._static_camera_frame = camera_frame_id

    def _path_msg(self, stamp: int, path: list[tuple[int, PoseFields]]) -> Path:
        """Return the path message, reusing the pose messages of poses that did not change."""
        cached, fresh = self._path_poses, {}
        for pose_stamp, pose in path:
            hit = cached.get(pose_stamp)
            fresh[pose_stamp] = (pose, hit[1] if hit is not None and hit[0] is pose else
                                 msg_builders.pose_stamped_msg(pose_stamp, self.world, pose))
        self._path_poses = fresh
        return Path(header=msg_builders.header(stamp, self.world),
                    poses=[message for _, message in fresh.values()])

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
                stamp, self.frames.wrist_frame_id(side),
                None if hand is None else hand.wrist_frame_landmarks))
