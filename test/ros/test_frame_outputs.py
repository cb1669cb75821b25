"""Engine results to output fields (ros/estimator/frame_outputs.py, vis/output_fields.py)."""

from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.ros.estimator.frame_outputs import frame_output
from infinihand_ros.vis.output_fields import hand_output
import numpy as np
from ros_builders import make_hand
from ros_builders import make_result
from ros_builders import PALM_JOINTS
from ros_builders import PALM_RIGHT_WRIST_ROTATION


def test_right_hand_wrist_frame_and_pose() -> None:
    """Palm in z = 0: wrist-frame joints are (p - wrist) @ R with R worked out by hand."""
    joints = PALM_JOINTS + np.array([1.0, 2.0, 3.0])
    out = hand_output(make_hand(RIGHT, joints_world=joints))
    np.testing.assert_allclose(out.landmarks_world, joints)
    np.testing.assert_allclose(out.wrist_frame_landmarks[5], [0.0, 0.02, 0.08], atol=1e-12)
    np.testing.assert_allclose(out.wrist_frame_landmarks[9], [0.0, 0.0, 0.09], atol=1e-12)
    np.testing.assert_allclose(out.wrist_frame_landmarks[0], np.zeros(3), atol=1e-12)
    np.testing.assert_allclose(out.wrist_pose.position, [1.0, 2.0, 3.0])
    rotation = geometry.quaternion_xyzw_to_matrix(out.wrist_pose.orientation_xyzw)
    np.testing.assert_allclose(rotation, PALM_RIGHT_WRIST_ROTATION, atol=1e-12)
    assert out.wrist_pose.orientation_xyzw[3] >= 0


def test_left_hand_uses_the_mirrored_axis_map() -> None:
    """Left: R = [[0, -1, 0], [0, 0, -1], [1, 0, 0]] (frame @ OPERATOR_TO_MANO[left])."""
    out = hand_output(make_hand(LEFT))
    np.testing.assert_allclose(out.wrist_frame_landmarks[5], [0.0, -0.02, 0.08], atol=1e-12)
    rotation = geometry.quaternion_xyzw_to_matrix(out.wrist_pose.orientation_xyzw)
    np.testing.assert_allclose(rotation, [[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]],
                               atol=1e-12)


def test_degenerate_or_unplaced_hands_count_as_not_seen() -> None:
    """No world joints, or collinear palm joints: no output (never made-up values)."""
    assert hand_output(make_hand(RIGHT, joints_world=None)) is None
    assert hand_output(make_hand(RIGHT, joints_world=np.zeros((21, 3)))) is None


def test_frame_output_keeps_stamp_pose_and_sides() -> None:
    """Stamp, T_world_cam and per-side slots come from the result."""
    pose = CameraPose(geometry.axis_angle_to_matrix(np.array([0.0, 0.0, np.pi / 2])),
                      np.array([0.5, 0.0, 1.0]))
    out = frame_output(make_result(123, (make_hand(RIGHT),), index=7, pose=pose, version=3))
    assert (out.stamp_ns, out.frame_index, out.pose_version) == (123, 7, 3)
    np.testing.assert_allclose(out.camera_pose.position, [0.5, 0.0, 1.0])
    np.testing.assert_allclose(out.camera_pose.orientation_xyzw,
                               [0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)
    assert out.hands[LEFT] is None and out.hands[RIGHT].side == RIGHT
