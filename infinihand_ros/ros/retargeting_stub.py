"""``retargeting_stub``: an example consumer of the estimator's ``~/hands`` and ``/tf``.

What a hand-retargeting node needs from one image: the followed hand's 21 joints relative to
its wrist, in the wrist frame (what dex-retargeting takes), and the wrist pose in the world frame
(the arm's target). The stub takes the hand from ``hands`` (``infinihand_msgs/HandFrame``; remap
it onto ``/infinihand_estimator/hands``) and the wrist pose from ``/tf`` at the image's stamp:
through ``tf2_ros.Buffer`` and ``TransformListener`` where tf2_ros is installed, else from the
``/tf`` messages it reads itself. It publishes ``~/wrist_pose`` (PoseStamped, world frame) and
``~/joints`` (PoseArray, the wrist frame), stamped with the image, where a retargeting
optimiser would take them. A hand frame waits (at most ``PENDING_KEPT``, newest kept) until its
transform has come; one without the followed hand publishes nothing.
"""

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
import importlib
import sys
from typing import Any, Final

from geometry_msgs.msg import PoseArray
from geometry_msgs.msg import PoseStamped
from geometry_msgs.msg import TransformStamped
from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.core import geometry
from infinihand_ros.core.config import config_from_dict
from infinihand_ros.core.hand_conventions import side_from_name
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.output_fields import PoseFields
from infinihand_ros.core.parameters import check_parameters
from infinihand_ros.core.parameters import parameter
from infinihand_ros.core.parameters import unflatten
from infinihand_ros.ros import msg_builders
from infinihand_ros.ros.estimator.publishers import HAND_FRAME_TYPE
from infinihand_ros.ros.estimator.publishers import message_type
from infinihand_ros.ros.estimator.publishers import OUTPUT_QOS
from infinihand_ros.ros.estimator.publishers import TF_QOS
from infinihand_ros.ros.estimator.publishers import TF_TOPIC
from infinihand_ros.ros.estimator.publishers import TF_TYPE
from infinihand_ros.ros.node_process import parse_command_line
from infinihand_ros.ros.node_process import run_node
from infinihand_ros.ros.parameters import declare_parameters
import numpy as np
from rclpy.node import Node
from rclpy.time import Time

NODE_NAME: Final = 'retargeting_stub'
#: Hand frames waiting for their transform, at most.
PENDING_KEPT: Final = 30
#: Transforms kept per stamp when reading /tf directly (a few seconds at camera rate).
TRANSFORMS_KEPT: Final = 300
#: How often waiting hand frames are tried again, s.
RETRY_PERIOD_S: Final = 0.02


@dataclass(frozen=True)
class RetargetingStubConfig:
    """The stub's parameters."""

    side: str = parameter('right', 'The hand to follow.', choices=SIDE_NAMES)
    world_frame_id: str = parameter('world', "The estimator's world frame on /tf.")
    wrist_frame_id: str = parameter('', "The followed hand's wrist frame on /tf; empty: "
                                    "'<side>_wrist', the estimator's default.")

    def __post_init__(self) -> None:
        check_parameters(self)

    @property
    def wrist_frame(self) -> str:
        """Return the wrist frame id looked up on /tf."""
        return self.wrist_frame_id or f'{self.side}_wrist'


class TopicTransforms:
    """World -> wrist transforms read from /tf directly, by stamp (no tf2_ros here)."""

    def __init__(self, node: Node, parent: str, child: str,
                 on_new: Callable[[], None]) -> None:
        """Subscribe to /tf; call ``on_new()`` after each parent -> child transform."""
        self.parent, self.child, self.on_new = parent, child, on_new
        self._by_stamp: OrderedDict[int, TransformStamped] = OrderedDict()
        node.create_subscription(message_type(TF_TYPE), TF_TOPIC,
                                 self._on_tf, TF_QOS)

    def lookup(self, stamp_ns: int) -> TransformStamped | None:
        """Return the transform stamped ``stamp_ns``, or None when it has not come."""
        return self._by_stamp.get(stamp_ns)

    def _on_tf(self, msg: Any) -> None:
        """Keep the transforms of our frame pair."""
        pair = (self.parent, self.child)
        for transform in msg.transforms:
            if (transform.header.frame_id, transform.child_frame_id) == pair:
                self._by_stamp[ns_from_stamp(transform.header.stamp)] = transform
                while len(self._by_stamp) > TRANSFORMS_KEPT:
                    self._by_stamp.popitem(last=False)
                self.on_new()


class BufferTransforms:
    """World -> wrist transforms from a tf2_ros Buffer filled by a TransformListener."""

    def __init__(self, node: Node, parent: str, child: str, tf2_ros: Any) -> None:
        """Start a TransformListener on the node."""
        self.parent, self.child = parent, child
        self.buffer = tf2_ros.Buffer()
        self.listener = tf2_ros.TransformListener(self.buffer, node)

    def lookup(self, stamp_ns: int) -> TransformStamped | None:
        """Return the transform at ``stamp_ns``, or None when tf2 cannot give it yet."""
        when = Time(nanoseconds=stamp_ns)
        if not self.buffer.can_transform(self.parent, self.child, when):
            return None
        return self.buffer.lookup_transform(self.parent, self.child, when)


def wrist_frame_joints(joints_world: np.ndarray, transform: TransformStamped) -> np.ndarray:
    """Return (21, 3) world joints in the wrist frame that a world -> wrist transform places."""
    translation, rotation = transform.transform.translation, transform.transform.rotation
    world_from_wrist = geometry.make_transform(
        geometry.quaternion_xyzw_to_matrix(np.array([rotation.x, rotation.y, rotation.z,
                                                     rotation.w])),
        np.array([translation.x, translation.y, translation.z]))
    return geometry.transform_points(geometry.invert_transform(world_from_wrist), joints_world)


class RetargetingStub(Node):
    """Pairs each hand frame with its wrist transform and publishes what retargeting takes."""

    def __init__(self, **node_kwargs: Any) -> None:
        """Declare the parameters, subscribe to ``hands`` and the transforms, make publishers."""
        super().__init__(NODE_NAME, **node_kwargs)
        self.config = declare_parameters(
            self, RetargetingStubConfig,
            lambda values: config_from_dict(RetargetingStubConfig, unflatten(values),
                                            NODE_NAME))
        self.side = side_from_name(self.config.side)
        world, wrist = self.config.world_frame_id, self.config.wrist_frame
        try:
            tf2_ros = importlib.import_module('tf2_ros')
        except ImportError:
            self.transforms: TopicTransforms | BufferTransforms = TopicTransforms(
                self, world, wrist, self._flush)
        else:
            self.transforms = BufferTransforms(self, world, wrist, tf2_ros)
        self._pending: OrderedDict[int, Any] = OrderedDict()  # image stamp -> the hand
        self.wrist_pose = self.create_publisher(PoseStamped, '~/wrist_pose',
                                                OUTPUT_QOS)
        self.joints = self.create_publisher(PoseArray, '~/joints', OUTPUT_QOS)
        self.create_subscription(message_type(HAND_FRAME_TYPE),
                                 'hands', self._on_hands, OUTPUT_QOS)
        self.create_timer(RETRY_PERIOD_S, self._flush)
        self.get_logger().info(f'following the {self.config.side} hand, wrist frame {wrist} in '
                               f'{world} ({type(self.transforms).__name__})')

    def close(self) -> None:
        """Nothing runs outside the executor."""

    def _on_hands(self, msg: Any) -> None:
        """Queue the followed hand of a frame (when seen and placed in the world)."""
        hand = next((h for h in msg.hands if h.side == self.side and h.has_world), None)
        if hand is None:
            return
        self._pending[ns_from_stamp(msg.header.stamp)] = hand
        while len(self._pending) > PENDING_KEPT:
            self._pending.popitem(last=False)
        self._flush()

    def _flush(self) -> None:
        """Publish every waiting hand whose transform has come."""
        for stamp_ns in list(self._pending):
            transform = self.transforms.lookup(stamp_ns)
            if transform is None:
                continue
            hand = self._pending.pop(stamp_ns)
            joints = np.array([[p.x, p.y, p.z] for p in hand.joints_world])
            translation, rotation = transform.transform.translation, transform.transform.rotation
            pose = PoseFields(np.array([translation.x, translation.y, translation.z]),
                              np.array([rotation.x, rotation.y, rotation.z, rotation.w]))
            self.wrist_pose.publish(msg_builders.pose_stamped_msg(
                stamp_ns, self.config.world_frame_id, pose))
            self.joints.publish(msg_builders.pose_array_msg(
                stamp_ns, self.config.wrist_frame, wrist_frame_joints(joints, transform)))


DESCRIPTION: Final = (
    "An example consumer of the estimator: each image's hand from ~/hands (remap hands:=\n"
    '/infinihand_estimator/hands) and its wrist from /tf, out as ~/wrist_pose (world frame)\n'
    'and ~/joints (21 joints in the wrist frame), what a retargeting node takes.')


def main(args: list[str] | None = None) -> int:
    """Run the stub until shut down (``--help``: print it and its parameters)."""
    parse_command_line(NODE_NAME, DESCRIPTION, RetargetingStubConfig, args)
    return run_node(RetargetingStub, NODE_NAME, args)


if __name__ == '__main__':
    sys.exit(main())
