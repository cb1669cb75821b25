"""An MCAP bag of one episode's estimates, viewable in Foxglove.

Topics (every header stamp is the source image's): ``/estimates/hand_frame``
(``infinihand_msgs/msg/HandFrame``: camera, intrinsics, full MANO per hand),
``/estimates/camera_pose`` (``geometry_msgs/msg/PoseStamped``, ``T_world_cam``) and
``/estimates/hands/{left,right}/landmarks`` (``geometry_msgs/msg/PoseArray``, 21 world joints in
OpenPose order; empty when the hand is not placed in the world).
"""

from pathlib import Path
from typing import Any, Final

from infinihand_ros.bag.messages import frame_result_to_msg
from infinihand_ros.bag.messages import pose_to_msg
from infinihand_ros.bag.messages import stamp_from_ns
from infinihand_ros.bag.typestore import HAND_FRAME_MSG
from infinihand_ros.bag.typestore import HEADER_MSG
from infinihand_ros.bag.typestore import POSE_STAMPED_MSG
from infinihand_ros.core import topics
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.hand_conventions import SIDES
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer
from rosbags.typesys.store import Typestore

POSE_ARRAY_MSG: Final = 'geometry_msgs/msg/PoseArray'
HAND_FRAME_TOPIC: Final = '/estimates/hand_frame'
CAMERA_POSE_TOPIC: Final = '/estimates/camera_pose'
LANDMARK_TOPICS: Final = tuple(f'/estimates/hands/{side}/landmarks' for side in SIDE_NAMES)
ROSBAG_VERSION: Final = 9
#: Orientation of a landmark pose (points have none).
POSE_IDENTITY: Final = CameraPose.identity().rotation


class EstimatesBagWriter:
    """Writes FrameResults into a new rosbag2 MCAP directory; ``close()`` finishes it."""

    def __init__(self, path: Path, typestore: Typestore) -> None:
        """Create the bag directory ``path`` (it must not exist)."""
        self.path = Path(path)
        self._store = typestore
        self._writer = Writer(self.path, version=ROSBAG_VERSION,
                              storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        wanted = {HAND_FRAME_TOPIC: HAND_FRAME_MSG, CAMERA_POSE_TOPIC: POSE_STAMPED_MSG,
                  **dict.fromkeys(LANDMARK_TOPICS, POSE_ARRAY_MSG)}
        self._connections = {topic: self._writer.add_connection(topic, msgtype,
                                                                typestore=typestore)
                             for topic, msgtype in wanted.items()}

    def write(self, result: FrameResult) -> None:
        """Write one frame's messages at its source stamp."""
        store, stamp = self._store, result.timestamp_ns
        header = store.types[HEADER_MSG](stamp=stamp_from_ns(store, stamp),
                                         frame_id=topics.WORLD_FRAME_ID)
        messages: dict[str, Any] = {
            HAND_FRAME_TOPIC: frame_result_to_msg(store, result, topics.WORLD_FRAME_ID),
            CAMERA_POSE_TOPIC: store.types[POSE_STAMPED_MSG](
                header=header, pose=pose_to_msg(store, result.camera_pose))}
        for side, topic in zip(SIDES, LANDMARK_TOPICS):
            hand = result.hand(side)
            joints = [] if hand is None or hand.joints_world is None else hand.joints_world
            messages[topic] = store.types[POSE_ARRAY_MSG](
                header=header, poses=[pose_to_msg(store, CameraPose(POSE_IDENTITY, point))
                                      for point in joints])
        for topic, msg in messages.items():
            connection = self._connections[topic]
            self._writer.write(connection, stamp, store.serialize_cdr(msg, connection.msgtype))

    def close(self) -> None:
        """Finish the bag (idempotent)."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None
