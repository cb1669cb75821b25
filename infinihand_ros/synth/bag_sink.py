"""Write synthetic frames to a rosbag2 bag (MCAP or sqlite3) with rosbags, atomically.

Topics (see ``core/topics.py``): ``/camera/image_raw`` (sensor_msgs/Image rgb8) or, with a jpeg or
png codec, ``/camera/image_raw/compressed`` (sensor_msgs/CompressedImage, as image_transport's
compressed plugin writes it), ``/camera/camera_info`` (sensor_msgs/CameraInfo),
``/ground_truth/camera_pose`` (geometry_msgs/PoseStamped, ``T_world_cam``, world = first camera)
and ``/ground_truth/hands`` (infinihand_msgs/HandFrame: every generated hand, ``confidence`` 1 when
visible and 0 when not).
Every header stamp is the frame's stamp.
"""

import contextlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from infinihand_ros.bag import camera_msgs
from infinihand_ros.bag.messages import frame_result_to_msg
from infinihand_ros.bag.messages import pose_to_msg
from infinihand_ros.bag.messages import stamp_from_ns
from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.bag.typestore import CAMERA_INFO_MSG
from infinihand_ros.bag.typestore import COMPRESSED_IMAGE_MSG
from infinihand_ros.bag.typestore import HAND_FRAME_MSG
from infinihand_ros.bag.typestore import HEADER_MSG
from infinihand_ros.bag.typestore import IMAGE_MSG
from infinihand_ros.bag.typestore import POSE_STAMPED_MSG
from infinihand_ros.core import topics
from infinihand_ros.core.atomic_io import atomic_directory
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.errors import InputError
from infinihand_ros.synth.sequence import HandTruth
from infinihand_ros.synth.sequence import SynthFrame
import numpy as np
from rosbags.rosbag2 import CompressionFormat
from rosbags.rosbag2 import CompressionMode
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer

STORAGE_PLUGINS: Final = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
ROSBAG_VERSION: Final = 9
#: Image codecs: 'raw' writes sensor_msgs/Image rgb8, the others sensor_msgs/CompressedImage.
IMAGE_CODECS: Final = ('raw',) + tuple(camera_msgs.CODEC_EXTENSIONS)
#: Topics written for every frame besides the image, with their message types.
OTHER_TOPICS: Final = (
    (topics.CAMERA_INFO_TOPIC, CAMERA_INFO_MSG),
    (topics.GT_CAMERA_POSE_TOPIC, POSE_STAMPED_MSG),
    (topics.GT_HANDS_TOPIC, HAND_FRAME_MSG),
)


@dataclass(frozen=True)
class BagOptions:
    """How a bag is stored.

    Attributes:
        storage: 'mcap' or 'sqlite3'.
        compress: zstd-compress the bag (MCAP chunks; ROS 2 reads them natively).
        image_codec: 'raw' (Image rgb8), 'jpeg' or 'png' (CompressedImage).
        jpeg_quality: JPEG quality 1..100 when ``image_codec`` is 'jpeg'.

    """

    storage: str = 'mcap'
    compress: bool = False
    image_codec: str = 'raw'
    jpeg_quality: int = 90

    def __post_init__(self) -> None:
        if self.storage not in STORAGE_PLUGINS:
            raise InputError(
                f'bag format must be one of {sorted(STORAGE_PLUGINS)}, got {self.storage!r}')
        if self.image_codec not in IMAGE_CODECS:
            raise InputError(
                f'image codec must be one of {list(IMAGE_CODECS)}, got {self.image_codec!r}')
        if not 1 <= self.jpeg_quality <= 100:
            raise InputError(f'jpeg_quality must be within 1..100, got {self.jpeg_quality}')

    def image_topic(self) -> tuple[str, str]:
        """Return the image topic and its message type."""
        if self.image_codec == 'raw':
            return topics.IMAGE_TOPIC, IMAGE_MSG
        return topics.COMPRESSED_IMAGE_TOPIC, COMPRESSED_IMAGE_MSG


def truth_to_hand_state(truth: HandTruth) -> HandState:
    """Ground truth of one hand as a ``HandState`` (confidence 1 if visible, else 0)."""
    return HandState(side=truth.side, mano_cam=truth.mano_cam, joints_cam=truth.joints_cam,
                     joints_2d=truth.joints_2d, box_xyxy=truth.box_xyxy,
                     confidence=1.0 if truth.visible else 0.0, mano_world=truth.mano_world,
                     joints_world=truth.joints_world)


class BagSink:
    """Context manager writing ``SynthFrame``s to a new bag directory at ``path``."""

    def __init__(self, path: str | Path, options: BagOptions | None = None) -> None:
        """Prepare a bag at ``path`` (must not exist) stored as ``options`` say."""
        self.path = Path(path)
        self.options = options or BagOptions()
        self.topics = (self.options.image_topic(),) + OTHER_TOPICS
        self.typestore = build_typestore()
        self._stack = contextlib.ExitStack()
        self._writer: Writer | None = None
        self._connections: dict = {}

    def __enter__(self) -> 'BagSink':
        """Open the bag under a temporary name."""
        work_path = self._stack.enter_context(atomic_directory(self.path))
        storage = self.options.storage
        writer = Writer(work_path, version=ROSBAG_VERSION, storage_plugin=STORAGE_PLUGINS[storage])
        if self.options.compress:
            mode = CompressionMode.STORAGE if storage == 'mcap' else CompressionMode.MESSAGE
            writer.set_compression(mode, CompressionFormat.ZSTD)
        writer.open()
        self._writer = writer
        self._connections = {topic: writer.add_connection(topic, msgtype, typestore=self.typestore)
                             for topic, msgtype in self.topics}
        return self

    def __exit__(self, exc_type: object, exc: object, traceback: object) -> None:
        """Close the bag; it appears at ``path`` only if no error happened."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        self._stack.__exit__(exc_type, exc, traceback)

    def add(self, frame: SynthFrame) -> None:
        """Write one frame's image, camera info and ground truth."""
        if self._writer is None:
            raise RuntimeError('BagSink.add called outside its with-block')
        store, stamp = self.typestore, frame.timestamp_ns
        header = store.types[HEADER_MSG](stamp=stamp_from_ns(store, stamp),
                                         frame_id=topics.WORLD_FRAME_ID)
        result = FrameResult(timestamp_ns=stamp, frame_index=frame.index,
                             camera_pose=frame.camera_pose, intrinsics=frame.intrinsics,
                             hands=tuple(truth_to_hand_state(h) for h in frame.hands))
        messages = {
            self.topics[0][0]: self._image_msg(frame.rgb, stamp),
            topics.CAMERA_INFO_TOPIC: camera_msgs.camera_info_to_msg(
                store, frame.intrinsics, stamp, topics.CAMERA_FRAME_ID),
            topics.GT_CAMERA_POSE_TOPIC: store.types[POSE_STAMPED_MSG](
                header=header, pose=pose_to_msg(store, frame.camera_pose)),
            topics.GT_HANDS_TOPIC: frame_result_to_msg(store, result, topics.WORLD_FRAME_ID),
        }
        for topic, msgtype in self.topics:
            self._writer.write(self._connections[topic], stamp,
                               store.serialize_cdr(messages[topic], msgtype))

    def _image_msg(self, rgb: np.ndarray, stamp: int) -> Any:
        """Build the frame's Image or CompressedImage message."""
        if self.options.image_codec == 'raw':
            return camera_msgs.image_to_msg(self.typestore, rgb, stamp, topics.CAMERA_FRAME_ID)
        return camera_msgs.image_to_compressed_msg(
            self.typestore, rgb, stamp, topics.CAMERA_FRAME_ID, self.options.image_codec,
            self.options.jpeg_quality)
