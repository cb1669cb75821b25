"""Camera frames of a bag, streamed, with every undecodable frame counted by reason.

Decoding is ``bag.camera_msgs`` (Image rgb8/bgr8/mono8, CompressedImage jpeg/png, CameraInfo);
the pairing follows ``bag.camera_stream``: an image takes the newest CameraInfo stored before
the next image, so an info stored just after its image is still used. Unlike
``camera_stream.read_camera_frames`` (which logs and forgets skipped frames), every skip and
warning here is counted in the episode's ``FrameLog`` with the topic named.
"""

from collections.abc import Callable
from collections.abc import Iterator
from pathlib import Path

from infinihand_ros.bag.camera_msgs import camera_info_to_intrinsics
from infinihand_ros.bag.camera_msgs import compressed_msg_to_image
from infinihand_ros.bag.camera_msgs import msg_to_image
from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.bag.reader import BagReader
from infinihand_ros.bag.typestore import COMPRESSED_IMAGE_MSG
from infinihand_ros.convert.frame_log import FrameLog
from infinihand_ros.convert.source_frames import SourceFrame
from infinihand_ros.convert.topic_selection import CameraTopics
from infinihand_ros.convert.topic_selection import select_camera_topics
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
import numpy as np

NO_CAMERA_INFO = 'no CameraInfo topic: intrinsics predicted by the model'
ZERO_STAMP = 'header stamp is zero: the bag time is used'


def read_bag_frames(bag: Path, image_topic: str | None, log: FrameLog) -> Iterator[SourceFrame]:
    """Yield the decodable camera frames of ``bag`` in bag order.

    Args:
        bag: rosbag2 directory, ``.mcap`` file or ROS 1 ``.bag`` file.
        image_topic: the image topic; auto-detected when None.
        log: receives the frames read, skipped (with the reason and topic) and warnings.

    Raises:
        BagError: for an unreadable bag, no (or an ambiguous) image topic, or a corrupt message.

    """
    with BagReader(bag) as reader:
        available = reader.topics()
        topics = select_camera_topics(available, str(bag), image_topic)
        compressed = available[topics.image].msgtype == COMPRESSED_IMAGE_MSG
        decode = compressed_msg_to_image if compressed else msg_to_image
        wanted = [topics.image] + ([topics.info] if topics.info else [])
        intrinsics: Intrinsics | None = None
        held: tuple[int, np.ndarray] | None = None
        for name, bag_time_ns, msg in reader.messages(wanted):
            if name == topics.info:
                intrinsics = _read_info(msg, topics, log) or intrinsics
                continue
            if held is not None:
                yield _frame(held, intrinsics, topics, log)
            held = _read_image(msg, decode, bag_time_ns, topics, log)
        if held is not None:
            yield _frame(held, intrinsics, topics, log)


def _read_info(msg: object, topics: CameraTopics, log: FrameLog) -> Intrinsics | None:
    try:
        return camera_info_to_intrinsics(msg)
    except InputError as exc:
        log.warn(f'topic {topics.info}: CameraInfo ignored ({exc})')
        return None


def _read_image(msg: object, decode: Callable[[object], np.ndarray], bag_time_ns: int,
                topics: CameraTopics, log: FrameLog) -> tuple[int, np.ndarray] | None:
    """Decode one image message; None (counted) when it cannot be used."""
    log.read += 1
    try:
        rgb = decode(msg)
    except InputError as exc:
        log.skip(f'topic {topics.image}: {exc}')
        return None
    stamp = ns_from_stamp(msg.header.stamp)
    if stamp == 0:
        log.warn(f'topic {topics.image}: {ZERO_STAMP}')
        stamp = int(bag_time_ns)
    return stamp, rgb


def _frame(held: tuple[int, np.ndarray], intrinsics: Intrinsics | None,
           topics: CameraTopics, log: FrameLog) -> SourceFrame:
    """Pair a held image with the intrinsics when they are for its size."""
    stamp, rgb = held
    if topics.info is None:
        log.warn(NO_CAMERA_INFO)
        return SourceFrame(stamp, rgb, None)
    size = (rgb.shape[1], rgb.shape[0])
    if intrinsics is not None and (intrinsics.width, intrinsics.height) != size:
        log.warn(f'topic {topics.info}: CameraInfo is for {intrinsics.width}x'
                 f'{intrinsics.height}, the image is {size[0]}x{size[1]}: intrinsics predicted')
        intrinsics = None
    elif intrinsics is None:
        log.warn(f'topic {topics.info}: no CameraInfo before this image: intrinsics predicted')
    return SourceFrame(stamp, rgb, intrinsics)
