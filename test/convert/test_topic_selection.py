"""Tests of infinihand_ros/convert/topic_selection.py: auto-detection and its errors."""

from infinihand_ros.bag.reader import TopicInfo
from infinihand_ros.convert.topic_selection import select_camera_topics
from infinihand_ros.core.errors import BagError
import pytest

IMAGE = TopicInfo('sensor_msgs/msg/Image', 5)
COMPRESSED = TopicInfo('sensor_msgs/msg/CompressedImage', 5)
INFO = TopicInfo('sensor_msgs/msg/CameraInfo', 5)
POSE = TopicInfo('geometry_msgs/msg/PoseStamped', 5)


def test_single_image_topic_and_sibling_info() -> None:
    """The only image topic is used with the CameraInfo beside it."""
    topics = {'/cam/image_raw/compressed': COMPRESSED, '/cam/camera_info': INFO,
              '/other/camera_info': INFO, '/pose': POSE}
    selected = select_camera_topics(topics, 'b', None)
    assert (selected.image, selected.info) == ('/cam/image_raw/compressed', '/cam/camera_info')


def test_ambiguous_topics_are_listed() -> None:
    """Two image topics: one error naming both and the flag to choose."""
    topics = {'/a/image_raw': IMAGE, '/b/image_raw': COMPRESSED}
    with pytest.raises(BagError, match=r'2 image topics.*--image-topic.*/a/image_raw.*'
                                       r'/b/image_raw'):
        select_camera_topics(topics, 'bag1', None)
    assert select_camera_topics(topics, 'bag1', '/b/image_raw').image == '/b/image_raw'


def test_missing_and_wrong_topics() -> None:
    """No image topic, or a requested topic that is not one, names what the bag has."""
    with pytest.raises(BagError, match=r'bag bag1 has no sensor_msgs Image.*/pose'):
        select_camera_topics({'/pose': POSE}, 'bag1', None)
    with pytest.raises(BagError, match=r'--image-topic /pose is not.*/a/image_raw'):
        select_camera_topics({'/pose': POSE, '/a/image_raw': IMAGE}, 'bag1', '/pose')


def test_no_camera_info() -> None:
    """Without CameraInfo the info topic is None; an unrelated single one is used."""
    assert select_camera_topics({'/a/image': IMAGE}, 'b', None).info is None
    assert select_camera_topics({'/a/image': IMAGE, '/x/info': INFO}, 'b', None).info == '/x/info'
