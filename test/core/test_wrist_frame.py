"""Tests of the dex-retargeting wrist frame."""

from infinihand_ros.core import geometry
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.wrist_frame import estimate_wrist_frame
from infinihand_ros.core.wrist_frame import keypoints_in_wrist_frame
import numpy as np
import pytest


def _palm_joints() -> np.ndarray:
    """Joints with wrist at 0, middle MCP along -x, index MCP towards +z (palm plane y = 0)."""
    joints = np.zeros((21, 3))
    joints[5] = [-0.09, 0.0, 0.02]
    joints[9] = [-0.095, 0.0, 0.0]
    joints[1:5] = [[-0.02, 0.0, 0.03]] * 4
    joints[10:21] = [[-0.12, 0.0, -0.01]] * 11
    return joints


def test_frame_axes_follow_the_definition() -> None:
    joints = _palm_joints()
    frame = estimate_wrist_frame(joints)
    np.testing.assert_allclose(frame.T @ frame, np.eye(3), atol=1e-12)
    assert np.linalg.det(frame) == pytest.approx(1.0)
    # x points from the middle MCP to the wrist: +x here; z from middle towards index MCP.
    np.testing.assert_allclose(frame[:, 0], [1.0, 0.0, 0.0], atol=1e-12)
    assert frame[:, 2] @ (joints[5] - joints[9]) > 0
    assert abs(frame[:, 1] @ [0.0, 1.0, 0.0]) == pytest.approx(1.0)


@pytest.mark.parametrize('side', [LEFT, RIGHT])
def test_keypoints_are_invariant_to_a_rigid_motion(side: int, rng: np.random.Generator) -> None:
    joints = _palm_joints() + rng.normal(scale=0.003, size=(21, 3))
    rotation = geometry.axis_angle_to_matrix(rng.normal(size=3))
    moved = joints @ rotation.T + rng.normal(size=3)
    local, _ = keypoints_in_wrist_frame(joints, side)
    local_moved, wrist_rotation = keypoints_in_wrist_frame(moved, side)
    np.testing.assert_allclose(local_moved, local, atol=1e-9)
    np.testing.assert_allclose(local_moved[0], 0.0, atol=1e-12)
    # The wrist rotation maps the local keypoints back to the moved, root-relative ones.
    np.testing.assert_allclose(local_moved @ wrist_rotation.T, moved - moved[0], atol=1e-9)


def test_right_hand_fingers_point_along_mano_z() -> None:
    local, _ = keypoints_in_wrist_frame(_palm_joints(), RIGHT)
    # operator-to-MANO maps the wrist->middle direction (-x of the frame) to +z.
    assert local[9, 2] > 0.09


def test_degenerate_palm_is_rejected() -> None:
    with pytest.raises(InputError, match='collinear'):
        estimate_wrist_frame(np.zeros((21, 3)))
    with pytest.raises(InputError, match=r'expected shape \(21, 3\)'):
        estimate_wrist_frame(np.zeros((20, 3)))
