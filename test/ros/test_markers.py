"""Skeleton and path markers (ros/markers.py)."""

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.ros.frame_outputs import hand_output
from infinihand_ros.ros.markers import BONES
from infinihand_ros.ros.markers import hand_markers
from infinihand_ros.ros.markers import LINE_LIST
from infinihand_ros.ros.markers import path_marker
from infinihand_ros.ros.markers import SIDE_COLOURS
from infinihand_ros.ros.markers import SPHERE_LIST
import numpy as np
from ros_builders import make_hand
from ros_builders import PALM_JOINTS


def test_bones_pair_each_joint_with_its_parent() -> None:
    """20 bones; the thumb tip's is (4, 3), the index MCP's (5, 0)."""
    assert len(BONES) == 20
    assert (4, 3) in BONES and (5, 0) in BONES


def test_seen_hand_gives_bones_and_joints_in_its_colour() -> None:
    """A LINE_LIST of 40 points (pairs) and a SPHERE_LIST of the 21 joints."""
    lines, spheres = hand_markers(RIGHT, hand_output(make_hand(RIGHT)))
    assert (lines.kind, spheres.kind) == (LINE_LIST, SPHERE_LIST)
    assert lines.points.shape == (40, 3)
    np.testing.assert_array_equal(lines.points[8], PALM_JOINTS[5])  # bone (5, 0): 5th pair
    np.testing.assert_array_equal(lines.points[9], PALM_JOINTS[0])
    np.testing.assert_array_equal(spheres.points, PALM_JOINTS)
    assert lines.rgba == SIDE_COLOURS[RIGHT] != SIDE_COLOURS[LEFT]
    assert not lines.delete and lines.namespace == 'right'


def test_unseen_hand_gives_deletions() -> None:
    """A hand not seen deletes both its markers (nothing stale on screen)."""
    markers = hand_markers(LEFT, None)
    assert [m.delete for m in markers] == [True, True]
    assert [m.marker_id for m in markers] == [0, 1]
    assert all(m.points.shape == (0, 3) for m in markers)


def test_path_marker_holds_the_positions() -> None:
    """The path is a strip through the camera positions."""
    positions = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    np.testing.assert_array_equal(path_marker(positions).points, positions)
