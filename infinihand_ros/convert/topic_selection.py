"""Which topics of a bag hold the camera: the image topic (auto-detected) and its CameraInfo."""

from dataclasses import dataclass

from infinihand_ros.bag.reader import TopicInfo
from infinihand_ros.bag.typestore import CAMERA_INFO_MSG
from infinihand_ros.bag.typestore import COMPRESSED_IMAGE_MSG
from infinihand_ros.bag.typestore import IMAGE_MSG
from infinihand_ros.core.errors import BagError

IMAGE_TYPES = (IMAGE_MSG, COMPRESSED_IMAGE_MSG)
#: Last name of an image_transport sub-topic (``<camera>/image_raw/compressed``).
COMPRESSED_SUFFIX = '/compressed'
INFO_NAME = 'camera_info'


@dataclass(frozen=True)
class CameraTopics:
    """The camera topics of one bag.

    Attributes:
        image: the Image or CompressedImage topic.
        info: the CameraInfo topic paired with it, or None when the bag has none.

    """

    image: str
    info: str | None


def _describe(topics: dict[str, TopicInfo], names: list[str]) -> str:
    return ', '.join(f'{name} ({topics[name].msgtype}, {topics[name].count} msgs)'
                     for name in names)


def select_image_topic(topics: dict[str, TopicInfo], bag: str, requested: str | None) -> str:
    """Return ``requested`` or the bag's only image topic.

    Raises:
        BagError: when ``requested`` is no image topic of the bag, or (without ``requested``)
            the bag has no image topic or more than one; the message lists the candidates.

    """
    candidates = sorted(name for name, info in topics.items() if info.msgtype in IMAGE_TYPES)
    if requested is not None:
        if requested not in candidates:
            raise BagError(f'bag {bag}: --image-topic {requested} is not an Image or '
                           f'CompressedImage topic of this bag; image topics: '
                           f'{_describe(topics, candidates) or "none"}')
        return requested
    if not candidates:
        raise BagError(f'bag {bag} has no sensor_msgs Image or CompressedImage topic; it has '
                       f'{_describe(topics, sorted(topics)) or "no topics"}')
    if len(candidates) > 1:
        raise BagError(f'bag {bag} has {len(candidates)} image topics, choose one with '
                       f'--image-topic: {_describe(topics, candidates)}')
    return candidates[0]


def select_info_topic(topics: dict[str, TopicInfo], image_topic: str) -> str | None:
    """Return the CameraInfo topic beside ``image_topic``, the bag's only one, or None."""
    infos = sorted(name for name, info in topics.items() if info.msgtype == CAMERA_INFO_MSG)
    base = image_topic.removesuffix(COMPRESSED_SUFFIX).rsplit('/', 1)[0]
    sibling = f'{base}/{INFO_NAME}'
    if sibling in infos:
        return sibling
    return infos[0] if len(infos) == 1 else None


def select_camera_topics(topics: dict[str, TopicInfo], bag: str,
                         requested: str | None) -> CameraTopics:
    """Return the image topic (see ``select_image_topic``) and its CameraInfo topic."""
    image = select_image_topic(topics, bag, requested)
    return CameraTopics(image, select_info_topic(topics, image))
