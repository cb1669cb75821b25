"""Camera frames from a bag: RGB images with their stamps and (when recorded) intrinsics.

Reads ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage`` (whichever the bag has on the
image topics) and pairs each image with the newest ``CameraInfo`` stored before the next image
(so an info stamped like its image is used even when the bag stores it just after the image).
Frames that cannot be decoded are skipped with a warning naming the frame, so one bad message
does not end a long conversion.
"""

from collections.abc import Iterator
from dataclasses import dataclass
import logging
from pathlib import Path

from infinihand_ros.bag.camera_msgs import camera_info_to_intrinsics
from infinihand_ros.bag.camera_msgs import compressed_msg_to_image
from infinihand_ros.bag.camera_msgs import msg_to_image
from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.bag.reader import BagReader
from infinihand_ros.bag.typestore import COMPRESSED_IMAGE_MSG
from infinihand_ros.bag.typestore import IMAGE_MSG
from infinihand_ros.core import topics
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import BagError
from infinihand_ros.core.errors import InputError
import numpy as np

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class CameraFrame:
    """One image of a bag.

    Attributes:
        timestamp_ns: the image header's stamp.
        rgb: (H, W, 3) uint8 RGB.
        intrinsics: from the newest CameraInfo before the next image (for this image size), or
            None.

    """

    timestamp_ns: int
    rgb: np.ndarray
    intrinsics: Intrinsics | None


def _image_topic(reader: BagReader, requested: str | None) -> str:
    """Return the image topic to read: ``requested`` or the bag's raw / compressed camera."""
    available = reader.topics()
    candidates = ([requested] if requested
                  else [topics.IMAGE_TOPIC, topics.COMPRESSED_IMAGE_TOPIC])
    for topic in candidates:
        if topic in available and available[topic].msgtype in (IMAGE_MSG, COMPRESSED_IMAGE_MSG):
            return topic
    raise BagError(f'bag {reader.path} has no image topic {candidates} of type Image or '
                   f'CompressedImage; it has {sorted(available)}; pass the topic to use')


def read_camera_frames(bag: str | Path, image_topic: str | None = None,
                       info_topic: str = topics.CAMERA_INFO_TOPIC,
                       max_frames: int | None = None) -> Iterator[CameraFrame]:
    """Yield the bag's camera frames in time order.

    Args:
        bag: rosbag2 directory.
        image_topic: Image or CompressedImage topic; the standard camera topics if None.
        info_topic: CameraInfo topic; frames carry no intrinsics if the bag lacks it.
        max_frames: stop after this many frames (None: all).

    Raises:
        BagError: for an unreadable bag or no usable image topic.

    """
    with BagReader(bag) as reader:
        topic = _image_topic(reader, image_topic)
        wanted = [topic] + ([info_topic] if info_topic in reader.topics() else [])
        intrinsics: Intrinsics | None = None
        held: tuple[int, np.ndarray] | None = None  # waits for a CameraInfo with its own stamp
        count = 0
        for name, _, msg in reader.messages(wanted):
            stamp = ns_from_stamp(msg.header.stamp)
            if name == info_topic:
                intrinsics = _read_info(msg, bag) or intrinsics
                continue
            if held is not None:
                yield _frame(held, intrinsics)
                count += 1
                if max_frames is not None and count >= max_frames:
                    return
            held = _read_image(msg, stamp, bag)
        if held is not None:
            yield _frame(held, intrinsics)


def _read_info(msg: object, bag: str | Path) -> Intrinsics | None:
    """Return a CameraInfo's intrinsics, or None (with a warning) when they are unusable."""
    try:
        return camera_info_to_intrinsics(msg)
    except InputError as exc:
        logger.warning('bag %s: ignoring a CameraInfo message (%s)', bag, exc)
        return None


def _read_image(msg: object, stamp: int, bag: str | Path) -> tuple[int, np.ndarray] | None:
    """Decode an Image or CompressedImage; None (with a warning) when it cannot be used."""
    try:
        rgb = compressed_msg_to_image(msg) if hasattr(msg, 'format') else msg_to_image(msg)
    except InputError as exc:
        logger.warning('bag %s: skipping the image stamped %d (%s)', bag, stamp, exc)
        return None
    return stamp, rgb


def _frame(held: tuple[int, np.ndarray], intrinsics: Intrinsics | None) -> CameraFrame:
    """Pair an image with the intrinsics when they are for its size."""
    stamp, rgb = held
    matching = intrinsics is not None and (intrinsics.width, intrinsics.height) == (
        rgb.shape[1], rgb.shape[0])
    return CameraFrame(stamp, rgb, intrinsics if matching else None)
