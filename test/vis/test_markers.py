"""Skeleton and path markers (vis/markers.py)."""

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.output_fields import HandOutput
from infinihand_ros.core.output_fields import PoseFields
from infinihand_ros.vis.markers import BONES
from infinihand_ros.vis.markers import hand_markers
from infinihand_ros.vis.markers import LINE_LIST
from infinihand_ros.vis.markers import path_marker
from infinihand_ros.vis.markers import SIDE_COLOURS
from infinihand_ros.vis.markers import SPHERE_LIST
import numpy as np

#: 21 distinct world joints: joint j at (3j, 3j + 1, 3j + 2), metres.
JOINTS = np.arange(63.0).reshape(21, 3)


def _seen_hand(side: int) -> HandOutput:
    """Return a seen hand at ``JOINTS`` (wrist-frame fields are not drawn)."""
    return HandOutput(side, 0.9, JOINTS.copy(), np.zeros((21, 3)),
                      PoseFields(JOINTS[0], np.array([0.0, 0.0, 0.0, 1.0])))


def test_bones_pair_each_joint_with_its_parent() -> None:
    """20 bones; the thumb tip's is (4, 3), the index MCP's (5, 0)."""
    assert len(BONES) == 20
    assert (4, 3) in BONES and (5, 0) in BONES


def test_seen_hand_gives_bones_and_joints_in_its_colour() -> None:
    """A LINE_LIST of 40 points (child, parent pairs) and a SPHERE_LIST of the 21 joints."""
    lines, spheres = hand_markers(RIGHT, _seen_hand(RIGHT))
    assert (lines.kind, spheres.kind) == (LINE_LIST, SPHERE_LIST)
    assert lines.points.shape == (40, 3)
    np.testing.assert_array_equal(lines.points[8], JOINTS[5])  # bone (5, 0): the 5th pair
    np.testing.assert_array_equal(lines.points[9], JOINTS[0])
    np.testing.assert_array_equal(spheres.points, JOINTS)
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
