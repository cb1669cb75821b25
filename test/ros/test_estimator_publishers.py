"""The estimator's /tf transforms, ~/hands and their broadcast (ros/estimator/publishers.py).

The messages are the generated ``tf2_msgs`` and ``infinihand_msgs`` types (``make`` builds them);
a missing package is tested by hiding its module. The node is a stand-in that records its
publishers.
"""

from dataclasses import dataclass
from dataclasses import field
import sys

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.output_fields import hand_output
from infinihand_ros.core.output_fields import PoseFields
from infinihand_ros.ros.estimator.config import FrameIds
from infinihand_ros.ros.estimator.config import OutputSwitches
from infinihand_ros.ros.estimator.config import TFSettings
import numpy as np
import pytest
from result_builders import make_hand
from result_builders import make_result
from result_builders import PALM_JOINTS
from result_builders import PALM_RIGHT_WRIST_ROTATION

publishers = pytest.importorskip('infinihand_ros.ros.estimator.publishers',
                                 reason='rclpy messages are not importable')

pytestmark = pytest.mark.ros
STAMP = 1_767_225_600_123_456_789
#: Camera turned 90 degrees about z (x -> y), at (1, 2, 3): quaternion (0, 0, sin 45, cos 45).
CAMERA = CameraPose(np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
                    np.array([1.0, 2.0, 3.0]))
CAMERA_XYZW = [0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)]
#: The right palm turned 90 degrees about x (y -> z) and moved to (0.4, 0.1, 0.5).
HAND_ROTATION = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
HAND_POSITION = np.array([0.4, 0.1, 0.5])
FRAMES = FrameIds(left_wrist_frame_id='operator/left_wrist',
                  right_wrist_frame_id='operator/right_wrist')


def _rotation(q) -> np.ndarray:
    """Return the rotation matrix of a geometry_msgs quaternion (textbook formula)."""
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _vector(v) -> np.ndarray:
    return np.array([v.x, v.y, v.z])


def _result():
    """Return a frame with the camera pose above, the right hand seen and the left not."""
    right = make_hand(RIGHT, joints_world=PALM_JOINTS @ HAND_ROTATION.T + HAND_POSITION)
    left = make_hand(LEFT, joints_world=None)  # detected, but not placed in the world
    return make_result(STAMP, (left, right), pose=CAMERA)


def _hands(result) -> dict:
    return {side: None if result.hand(side) is None else hand_output(result.hand(side))
            for side in (LEFT, RIGHT)}


def test_transforms_are_the_camera_pose_and_the_wrist_pose() -> None:
    """World -> camera is camera-to-world, world -> wrist the wrist frame; xyzw; image stamp."""
    result = _result()
    hands = _hands(result)
    assert hands[LEFT] is None
    camera, wrist = publishers.frame_transforms(result, hands, FRAMES, 'head_camera_optical')
    for transform in (camera, wrist):
        assert (transform.header.stamp.sec, transform.header.stamp.nanosec) == (
            1_767_225_600, 123_456_789)
        assert transform.header.frame_id == 'world'
    assert camera.child_frame_id == 'head_camera_optical'
    rotation = camera.transform.rotation
    np.testing.assert_allclose([rotation.x, rotation.y, rotation.z, rotation.w], CAMERA_XYZW,
                               atol=1e-12)
    np.testing.assert_allclose(_vector(camera.transform.translation), [1.0, 2.0, 3.0])
    assert wrist.child_frame_id == 'operator/right_wrist'
    np.testing.assert_allclose(_vector(wrist.transform.translation), HAND_POSITION, atol=1e-12)
    np.testing.assert_allclose(_rotation(wrist.transform.rotation),
                               HAND_ROTATION @ PALM_RIGHT_WRIST_ROTATION, atol=1e-12)
    # What a TF listener does with the wrist-frame landmarks: back to the world landmarks.
    in_world = (hands[RIGHT].wrist_frame_landmarks @ _rotation(wrist.transform.rotation).T
                + _vector(wrist.transform.translation))
    np.testing.assert_allclose(in_world, hands[RIGHT].landmarks_world, atol=1e-12)


def test_camera_transform_left_out_when_asked_or_when_it_is_the_world() -> None:
    """No camera frame, or the world's own id (a static camera as world): wrists only."""
    result = _result()
    for camera_frame in (None, 'world'):
        transforms = publishers.frame_transforms(result, _hands(result), FRAMES, camera_frame)
        assert [t.child_frame_id for t in transforms] == ['operator/right_wrist']


@dataclass
class _Publisher:
    msg_type: type
    topic: str
    qos: object
    sent: list = field(default_factory=list)

    def publish(self, msg: object) -> None:
        self.sent.append(msg)


@dataclass
class _Node:
    """The one thing OutputPublishers asks of its node: publishers."""

    publishers: dict = field(default_factory=dict)

    def create_publisher(self, msg_type: type, topic: str, qos: object) -> _Publisher:
        self.publishers[topic] = _Publisher(msg_type, topic, qos)
        return self.publishers[topic]


@pytest.fixture
def generated() -> tuple[type, type]:
    """Return the generated TFMessage and HandFrame classes (skip where not built)."""
    tf2_msgs = pytest.importorskip('tf2_msgs.msg', reason='tf2_msgs is not built (make)')
    infinihand_msgs = pytest.importorskip('infinihand_msgs.msg',
                                          reason='infinihand_msgs is not built (make)')
    return tf2_msgs.TFMessage, infinihand_msgs.HandFrame


def _publish_frames(tf: TFSettings, count: int = 3, static_camera: bool = False) -> _Node:
    """Publish ``count`` frames through OutputPublishers on a stand-in node; return it."""
    node = _Node()
    outputs = publishers.OutputPublishers(node, OutputSwitches(), FRAMES, tf, static_camera)
    for _ in range(count):
        outputs.publish(_result(), 'head_camera_optical', None)
    return node


@pytest.mark.parametrize('module,switch', [('tf2_msgs.msg', 'tf.enabled'),
                                           ('infinihand_msgs.msg', 'outputs.hand_frame')])
def test_a_missing_message_package_stops_the_start_naming_it_and_its_switch(
        generated: tuple[type, type], monkeypatch: pytest.MonkeyPatch, module: str,
        switch: str) -> None:
    """No silent gap: the error names the package, how to build it and the switch."""
    monkeypatch.setitem(sys.modules, module, None)  # the import fails as where it is not built
    with pytest.raises(ConfigError, match=f'{module.split(".")[0]} cannot be imported.*make.*'
                                          f'{switch}:=false'):
        _publish_frames(TFSettings())


def test_each_frame_is_one_tf_message(generated: tuple[type, type]) -> None:
    """A TFMessage per frame on /tf with tf2_ros's QoS: camera and the seen wrist."""
    node = _publish_frames(TFSettings())
    tf = node.publishers[publishers.TF_TOPIC]
    assert tf.msg_type is generated[0] and tf.qos.depth == 100
    assert len(tf.sent) == 3 and publishers.TF_STATIC_TOPIC not in node.publishers
    assert [t.child_frame_id for t in tf.sent[-1].transforms] == [
        'head_camera_optical', 'operator/right_wrist']
    np.testing.assert_allclose(_vector(tf.sent[-1].transforms[0].transform.translation),
                               [1.0, 2.0, 3.0])
    # Wrist-frame landmarks are stamped with the frame the TF gives.
    landmarks = node.publishers['~/hands/right/wrist_frame_landmarks'].sent[-1]
    assert landmarks.header.frame_id == 'operator/right_wrist'


def test_a_fixed_camera_goes_once_to_tf_static(generated: tuple[type, type]) -> None:
    """A fixed camera (profile teleop): world -> camera once on /tf_static; /tf has the wrists."""
    node = _publish_frames(TFSettings(), static_camera=True)
    static = node.publishers[publishers.TF_STATIC_TOPIC]
    assert static.qos.durability == publishers.LATCHED_QOS.durability
    (sent,) = static.sent
    (camera,) = sent.transforms
    assert (camera.header.frame_id, camera.child_frame_id) == ('world', 'head_camera_optical')
    assert camera.header.stamp.sec == 1_767_225_600
    assert [t.child_frame_id for t in node.publishers[publishers.TF_TOPIC].sent[-1].transforms
            ] == ['operator/right_wrist']
    no_camera = _publish_frames(TFSettings(camera=False), static_camera=True)
    assert publishers.TF_STATIC_TOPIC not in no_camera.publishers


def test_tf_switches(generated: tuple[type, type]) -> None:
    """tf.camera false: wrists only; tf.enabled false: no /tf publisher."""
    wrists_only = _publish_frames(TFSettings(camera=False)).publishers[publishers.TF_TOPIC]
    assert [t.child_frame_id for t in wrists_only.sent[-1].transforms] == [
        'operator/right_wrist']
    off = _publish_frames(TFSettings(enabled=False))
    assert publishers.TF_TOPIC not in off.publishers


def test_hands_is_one_hand_frame_per_image(generated: tuple[type, type]) -> None:
    """~/hands: the camera pose and both detected hands, as the estimates bag writes them."""
    serialization = pytest.importorskip('rclpy.serialization')
    node = _publish_frames(TFSettings(enabled=False), count=1)
    hands = node.publishers[publishers.HAND_FRAME_TOPIC]
    assert hands.msg_type is generated[1]
    msg = serialization.deserialize_message(hands.sent[0], generated[1])
    assert msg.header.frame_id == 'world' and msg.header.stamp.nanosec == 123_456_789
    np.testing.assert_allclose(_vector(msg.camera_pose.position), [1.0, 2.0, 3.0])
    left, right = msg.hands
    assert (left.side, left.has_world, right.side, right.has_world) == (LEFT, False, RIGHT, True)
    assert right.confidence == pytest.approx(0.9)
    np.testing.assert_allclose([_vector(p) for p in right.joints_world],
                               PALM_JOINTS @ HAND_ROTATION.T + HAND_POSITION)
    assert len(right.mano_world.hand_pose) == 45
    node = _Node()
    publishers.OutputPublishers(node, OutputSwitches(hand_frame=False), FRAMES,
                                TFSettings(enabled=False))
    assert publishers.HAND_FRAME_TOPIC not in node.publishers


def test_the_path_reuses_the_messages_of_unchanged_poses() -> None:
    """A path message equals one built afresh; poses that did not change keep their messages."""
    msg_builders = pytest.importorskip('infinihand_ros.ros.msg_builders')
    node = _Node()
    outputs = publishers.OutputPublishers(node, OutputSwitches(hand_frame=False), FRAMES,
                                          TFSettings(enabled=False))
    poses = [(stamp, PoseFields(np.array([stamp, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0])))
             for stamp in (10, 20, 30)]
    outputs.publish(_result(), 'camera', poses[:2])
    refreshed = (20, PoseFields(np.array([5.0, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0])))
    outputs.publish(_result(), 'camera', [poses[0], refreshed, poses[2]])
    first, second = node.publishers['~/camera_path'].sent
    assert second == msg_builders.path_msg(STAMP, 'world', [poses[0], refreshed, poses[2]])
    assert second.poses[0] is first.poses[0]  # unchanged: the same message
    assert second.poses[1] is not first.poses[1]  # refreshed: built again
    assert second.poses[1].pose.position.x == 5.0
