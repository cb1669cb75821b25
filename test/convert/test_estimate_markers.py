"""Markers of the bag of estimates (convert/estimate_markers.py, convert/estimates_bag.py)."""

from pathlib import Path
import subprocess
import sys

from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.bag.reader import BagReader
from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.convert.estimates_bag import EstimatesBagWriter
from infinihand_ros.convert.estimates_bag import LANDMARK_TOPICS
from infinihand_ros.convert.estimates_bag import MARKERS_TOPIC
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.vis.markers import BONES
from infinihand_ros.vis.markers import PATH_COLOUR
from infinihand_ros.vis.markers import SIDE_COLOURS
import numpy as np
import pytest

STAMP_NS = 1_767_225_600_000_000_000
PERIOD_NS = 100_000_000


def _right_hand(joints_world: np.ndarray) -> HandState:
    mano = ManoParams(np.zeros(3), np.zeros((15, 3)), np.zeros(10), np.zeros(3))
    return HandState(RIGHT, mano, joints_world.copy(), np.zeros((21, 2)),
                     np.array([0.0, 0.0, 10.0, 10.0]), 0.8, mano_world=mano,
                     joints_world=joints_world)


def _results(joints: np.ndarray) -> list[FrameResult]:
    """Three frames: the camera moves along x; the right hand is seen, the left is not."""
    return [FrameResult(STAMP_NS + k * PERIOD_NS, k,
                        CameraPose(np.eye(3), np.array([0.1 * k, 0.0, 0.0])),
                        Intrinsics(100.0, 100.0, 80.0, 60.0, 160, 120),
                        hands=(_right_hand(joints),)) for k in range(3)]


def test_marker_arrays_show_skeletons_and_the_bounded_path(tmp_path: Path) -> None:
    """Each frame: left deleted, right bones/joints in orange, the newest 2 camera positions.

    The landmark arrays beside them hold the right hand's 21 joints and no left joint.
    """
    joints = np.random.default_rng(0).normal(size=(21, 3))
    bag = tmp_path / 'estimates'
    writer = EstimatesBagWriter(bag, build_typestore(), path_length=2)
    for result in _results(joints):
        writer.write(result)
    writer.close()
    with BagReader(bag) as reader:
        messages = list(reader.messages([MARKERS_TOPIC]))
        landmarks = {name: msg for name, _, msg in reader.messages(list(LANDMARK_TOPICS))}
    assert len(messages) == 3
    left, right = (landmarks[topic].poses for topic in LANDMARK_TOPICS)
    assert left == [] and {pose.orientation.w for pose in right} == {1.0}
    np.testing.assert_allclose([[p.position.x, p.position.y, p.position.z] for p in right],
                               joints)
    _, bag_time, last = messages[-1]
    assert bag_time == STAMP_NS + 2 * PERIOD_NS
    markers = {(m.ns, m.id): m for m in last.markers}
    assert sorted(markers) == [('camera_path', 0), ('left', 0), ('left', 1), ('right', 0),
                               ('right', 1)]
    for marker in last.markers:
        assert ns_from_stamp(marker.header.stamp) == bag_time
        assert marker.header.frame_id == 'world'
    assert {markers['left', i].action for i in (0, 1)} == {last.markers[0].DELETE}
    bones, spheres = markers['right', 0], markers['right', 1]
    assert (bones.type, spheres.type) == (bones.LINE_LIST, bones.SPHERE_LIST)
    bone_points = np.array([[p.x, p.y, p.z] for p in bones.points])
    np.testing.assert_allclose(bone_points, joints[np.array(BONES).reshape(-1)])
    np.testing.assert_allclose([[p.x, p.y, p.z] for p in spheres.points], joints)
    colour = (bones.color.r, bones.color.g, bones.color.b, bones.color.a)
    np.testing.assert_allclose(colour, SIDE_COLOURS[RIGHT], rtol=1e-6)
    path = markers['camera_path', 0]
    assert path.type == path.LINE_STRIP and path.action == path.ADD
    np.testing.assert_allclose([[p.x, p.y, p.z] for p in path.points],
                               [[0.1, 0.0, 0.0], [0.2, 0.0, 0.0]])
    np.testing.assert_allclose((path.color.r, path.color.a), PATH_COLOUR[::3], rtol=1e-6)


@pytest.mark.parametrize('module', ['infinihand_ros.convert.cli',
                                    'infinihand_ros.convert.estimate_markers'])
def test_converter_imports_no_rclpy(module: str) -> None:
    """The converter runs without a ROS runtime: rclpy is never imported."""
    code = (f'import sys, {module}; '
            "sys.exit(1 if any(m.split('.')[0] == 'rclpy' for m in sys.modules) else 0)")
    assert subprocess.run([sys.executable, '-c', code], check=False).returncode == 0
