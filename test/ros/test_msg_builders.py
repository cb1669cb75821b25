"""rclpy output messages from the plain output fields (ros/msg_builders.py)."""

import dataclasses

from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.output_fields import hand_output
from infinihand_ros.core.output_fields import PoseFields
from infinihand_ros.ros.estimator.diagnostics import DiagnosticReport
from infinihand_ros.vis.markers import hand_markers
import numpy as np
import pytest
from result_builders import INTRINSICS
from result_builders import make_hand
from result_builders import PALM_JOINTS

msg_builders = pytest.importorskip('infinihand_ros.ros.msg_builders',
                                   reason='rclpy messages are not importable')
Marker = pytest.importorskip('visualization_msgs.msg').Marker

pytestmark = pytest.mark.ros
STAMP = 1_767_225_600_123_456_789
POSE = PoseFields(np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)]))


def test_header_stamp_is_the_source_stamp() -> None:
    """Nanoseconds split into sec and nanosec exactly."""
    header = msg_builders.header(STAMP, 'world')
    assert (header.stamp.sec, header.stamp.nanosec, header.frame_id) == (
        1_767_225_600, 123_456_789, 'world')


def test_pose_and_pose_array() -> None:
    """Pose fields are copied; a PoseArray holds one pose per point, empty for None."""
    msg = msg_builders.pose_stamped_msg(STAMP, 'world', POSE)
    assert (msg.pose.position.x, msg.pose.position.z) == (1.0, 3.0)
    assert msg.pose.orientation.w == pytest.approx(np.sqrt(0.5))
    array = msg_builders.pose_array_msg(STAMP, 'world', PALM_JOINTS)
    assert len(array.poses) == 21 and array.poses[5].position.x == 0.02
    assert array.poses[5].orientation.w == 1.0
    assert msg_builders.pose_array_msg(STAMP, 'world', None).poses == []


def test_path_markers_camera_info_names_and_diagnostics() -> None:
    """Each builder carries the stamp and the given values."""
    path = msg_builders.path_msg(STAMP, 'world', [(5, POSE), (STAMP, POSE)])
    assert [ps.header.stamp.nanosec for ps in path.poses] == [5, 123_456_789]
    markers = msg_builders.marker_array_msg(
        STAMP, 'world', hand_markers(RIGHT, hand_output(make_hand(RIGHT))))
    assert [m.type for m in markers.markers] == [Marker.LINE_LIST, Marker.SPHERE_LIST]
    assert len(markers.markers[0].points) == 40 and markers.markers[0].action == Marker.ADD
    info = msg_builders.camera_info_msg(STAMP, 'cam_optical', INTRINSICS)
    assert list(info.k) == [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]
    assert (info.width, info.height, info.p[2], info.p[3]) == (640, 480, 320.0, 0.0)
    assert (info.distortion_model, list(info.d)) == ('plumb_bob', [0.0] * 5)
    fisheye = dataclasses.replace(INTRINSICS, distortion_model='equidistant',
                                  distortion=(0.05, -0.01, 0.003, -0.001))
    info = msg_builders.camera_info_msg(STAMP, 'cam_optical', fisheye)
    assert (info.distortion_model, list(info.d)) == ('equidistant', [0.05, -0.01, 0.003, -0.001])
    names = msg_builders.joint_names_msg().data.split(',')
    assert len(names) == 21 and names[0] == 'wrist' and names[20] == 'pinky_tip'
    report = DiagnosticReport(1, 'slow', (('input_rate_hz', '10.000'),))
    status = msg_builders.diagnostic_array_msg(STAMP, 'est', 'hw', report).status[0]
    assert status.level == b'\x01' and status.values[0].value == '10.000'
