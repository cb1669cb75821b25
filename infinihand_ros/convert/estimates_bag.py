"""An MCAP bag of one episode's estimates, viewable in Foxglove.

Topics (every header stamp is the source image's): ``/estimates/hand_frame``
(``infinihand_msgs/msg/HandFrame``: camera, intrinsics, full MANO per hand),
``/estimates/camera_pose`` (``geometry_msgs/msg/PoseStamped``, ``T_world_cam``) and
``/estimates/hands/{left,right}/landmarks`` (``geometry_msgs/msg/PoseArray``, 21 world joints in
OpenPose order; empty when the hand is not placed in the world) and ``/estimates/markers``
(``visualization_msgs/msg/MarkerArray``: both hand skeletons and the camera path of the newest
``path_length`` frames, ``convert.estimate_markers``) and ``/estimates/camera_info``
(``sensor_msgs/msg/CameraInfo`` of the intrinsics used, with the lens distortion model and
coefficients, in the camera frame). Every other frame is in the world frame.
"""

from pathlib import Path
from typing import Any, Final

from infinihand_ros.bag.camera_msgs import camera_info_to_msg
from infinihand_ros.bag.messages import frame_result_to_msg
from infinihand_ros.bag.messages import pose_to_msg
from infinihand_ros.bag.messages import stamp_from_ns
from infinihand_ros.bag.typestore import CAMERA_INFO_MSG
from infinihand_ros.bag.typestore import HAND_FRAME_MSG
from infinihand_ros.bag.typestore import HEADER_MSG
from infinihand_ros.bag.typestore import POINT_MSG
from infinihand_ros.bag.typestore import POSE_MSG
from infinihand_ros.bag.typestore import POSE_STAMPED_MSG
from infinihand_ros.bag.typestore import QUATERNION_MSG
from infinihand_ros.convert.estimate_markers import CameraPathPoints
from infinihand_ros.convert.estimate_markers import frame_marker_specs
from infinihand_ros.convert.estimate_markers import MARKER_ARRAY_MSG
from infinihand_ros.convert.estimate_markers import marker_array_msg
from infinihand_ros.core import topics
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.hand_conventions import SIDES
import numpy as np
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer
from rosbags.typesys.store import Typestore

POSE_ARRAY_MSG: Final = 'geometry_msgs/msg/PoseArray'
HAND_FRAME_TOPIC: Final = '/estimates/hand_frame'
CAMERA_POSE_TOPIC: Final = '/estimates/camera_pose'
LANDMARK_TOPICS: Final = tuple(f'/estimates/hands/{side}/landmarks' for side in SIDE_NAMES)
MARKERS_TOPIC: Final = '/estimates/markers'
CAMERA_INFO_TOPIC: Final = '/estimates/camera_info'
ROSBAG_VERSION: Final = 9


def _landmark_msgs(store: Typestore, joints: np.ndarray | None) -> list[Any]:
    """Return Pose messages of (21, 3) world joints (identity orientations; none for None)."""
    if joints is None:
        return []
    pose, point, quaternion = (store.types[name]
                               for name in (POSE_MSG, POINT_MSG, QUATERNION_MSG))
    return [pose(position=point(x=float(x), y=float(y), z=float(z)),
                 orientation=quaternion(x=0.0, y=0.0, z=0.0, w=1.0)) for x, y, z in joints]


class EstimatesBagWriter:
    """Writes FrameResults into a new rosbag2 MCAP directory; ``close()`` finishes it."""

    def __init__(self, path: Path, typestore: Typestore, path_length: int) -> None:
        """Create the bag directory ``path`` (it must not exist).

        Args:
            path: the new bag directory.
            typestore: a typestore of ``bag.typestore.build_typestore()``.
            path_length: camera positions in the path marker (the newest are kept).

        """
        self.path = Path(path)
        self._store = typestore
        self._camera_path = CameraPathPoints(path_length)
        self._writer = Writer(self.path, version=ROSBAG_VERSION,
                              storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        wanted = {HAND_FRAME_TOPIC: HAND_FRAME_MSG, CAMERA_POSE_TOPIC: POSE_STAMPED_MSG,
                  **dict.fromkeys(LANDMARK_TOPICS, POSE_ARRAY_MSG),
                  MARKERS_TOPIC: MARKER_ARRAY_MSG, CAMERA_INFO_TOPIC: CAMERA_INFO_MSG}
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
                header=header, pose=pose_to_msg(store, result.camera_pose)),
            CAMERA_INFO_TOPIC: camera_info_to_msg(store, result.intrinsics, stamp,
                                                  topics.CAMERA_FRAME_ID)}
        for side, topic in zip(SIDES, LANDMARK_TOPICS):
            hand = result.hand(side)
            messages[topic] = store.types[POSE_ARRAY_MSG](
                header=header, poses=_landmark_msgs(store, None if hand is None
                                                    else hand.joints_world))
        path = self._camera_path.add(result.camera_pose.translation)
        messages[MARKERS_TOPIC] = marker_array_msg(store, stamp, topics.WORLD_FRAME_ID,
                                                   frame_marker_specs(result, path))
        for topic, msg in messages.items():
            connection = self._connections[topic]
            self._writer.write(connection, stamp, store.serialize_cdr(msg, connection.msgtype))

    def close(self) -> None:
        """Finish the bag (idempotent)."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None
