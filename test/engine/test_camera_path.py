"""The bounded, refreshable camera path (engine/output/camera_path.py)."""

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.output_fields import PoseFields
from infinihand_ros.engine.output.camera_path import CameraPath
import numpy as np


def pose(x: float) -> PoseFields:
    """Return a pose at (x, 0, 0)."""
    return PoseFields(np.array([x, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0]))


def test_path_is_bounded_oldest_out() -> None:
    """Only the newest capacity poses stay, oldest first."""
    path = CameraPath(2)
    for index in range(3):
        path.add(index, 100 + index, pose(index), 0)
    assert [stamp for stamp, _ in path.poses()] == [101, 102]
    assert len(path) == 2


def camera(x: float) -> CameraPose:
    """Return a camera pose at (x, 0, 0), turned 90 degrees about z."""
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    return CameraPose(rotation, np.array([x, 0.0, 0.0]))


def test_new_version_rereads_known_poses_when_the_path_goes_out() -> None:
    """A new pose version: poses the lookup still knows are re-read at the next publication."""
    path = CameraPath(10)
    path.add(0, 100, pose(0.0), 0)
    path.add(1, 101, pose(1.0), 0)
    looked_up = []

    def lookup(index: int) -> CameraPose | None:
        looked_up.append(index)
        return {0: camera(10.0)}.get(index)

    path.add(2, 102, pose(2.0), 1, lookup)
    assert looked_up == [] and [p.position[0] for _, p in path.poses()] == [0.0, 1.0, 2.0]
    path.add(3, 103, pose(3.0), 1, {1: camera(99.0)}.get)  # same version: nothing more to read
    poses = path.poses_due(103, period_ns=0)
    assert sorted(looked_up) == [0, 1, 2, 3]
    assert [p.position[0] for _, p in poses] == [10.0, 1.0, 2.0, 3.0]
    np.testing.assert_allclose(poses[0][1].orientation_xyzw, [0.0, 0.0, np.sqrt(0.5),
                                                              np.sqrt(0.5)])
    looked_up.clear()
    path.poses_due(104, period_ns=0)
    assert looked_up == []  # read once per version change


def test_publication_is_paced_by_image_time_and_refined_poses_go_out_with_it() -> None:
    """Due with the first frame, then once per period of image time; a new version waits for it."""
    path = CameraPath(10)
    due = []
    for index, stamp in enumerate([0, 400, 900, 1000, 1500, 2100]):
        path.add(index, stamp, pose(index), 0)
        due.append(path.poses_due(stamp, period_ns=1000) is not None)
    assert due == [True, False, False, True, False, True]
    path.add(6, 2200, pose(6.0), 1, {0: camera(10.0)}.get)  # a new version
    assert path.poses_due(2200, period_ns=1000) is None
    assert path.poses_due(3100, period_ns=1000)[0][1].position[0] == 10.0
    assert path.poses_due(3200, period_ns=0) is not None  # period 0: every frame
    path.clear()
    path.add(0, 5, pose(0.0), 0)
    assert path.poses_due(5, period_ns=1000) is not None  # a new stream starts afresh
