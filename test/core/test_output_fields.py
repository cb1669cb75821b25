"""Output fields of engine hands and poses (core/output_fields.py), worked out by hand."""

from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.output_fields import hand_output
from infinihand_ros.core.output_fields import PoseFields
import numpy as np
from result_builders import make_hand
from result_builders import PALM_JOINTS
from result_builders import PALM_RIGHT_WRIST_ROTATION


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


def test_pose_fields_of_a_camera_pose() -> None:
    """T_world_cam's translation and its rotation as (x, y, z, w) with w >= 0."""
    pose = CameraPose(geometry.axis_angle_to_matrix(np.array([0.0, 0.0, np.pi / 2])),
                      np.array([0.5, 0.0, 1.0]))
    fields = PoseFields.from_camera_pose(pose)
    np.testing.assert_allclose(fields.position, [0.5, 0.0, 1.0])
    np.testing.assert_allclose(fields.orientation_xyzw, [0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)],
                               atol=1e-12)
