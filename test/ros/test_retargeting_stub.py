"""The retargeting stub's parameters and its wrist-frame joints (ros/retargeting_stub.py)."""

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.output_fields import hand_output
import numpy as np
import pytest
from result_builders import make_hand
from result_builders import PALM_JOINTS

stub = pytest.importorskip('infinihand_ros.ros.retargeting_stub', reason='needs rclpy')
msg_builders = pytest.importorskip('infinihand_ros.ros.msg_builders')

pytestmark = pytest.mark.ros


def test_wrist_frame_joints_are_the_estimators_wrist_frame_landmarks() -> None:
    """Through the /tf transform of the wrist pose: the node's own wrist-frame landmarks."""
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    hand = hand_output(make_hand(1, joints_world=PALM_JOINTS @ rotation.T + [0.3, 0.2, 0.1]))
    transform = msg_builders.transform_stamped_msg(5, 'world', 'right_wrist', hand.wrist_pose)
    np.testing.assert_allclose(stub.wrist_frame_joints(hand.landmarks_world, transform),
                               hand.wrist_frame_landmarks, atol=1e-12)


def test_config_defaults_and_choices() -> None:
    """The wrist frame follows the side unless named; an unknown side is refused."""
    assert stub.RetargetingStubConfig().wrist_frame == 'right_wrist'
    assert stub.RetargetingStubConfig(side='left').wrist_frame == 'left_wrist'
    assert stub.RetargetingStubConfig(wrist_frame_id='op/r').wrist_frame == 'op/r'
    with pytest.raises(ConfigError, match='side'):
        stub.RetargetingStubConfig(side='both')
