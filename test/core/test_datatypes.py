"""Tests of the boundary dataclasses: construction, conversions and input errors."""

from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.errors import InputError
import numpy as np
import pytest


def test_intrinsics_matrix_and_fov_round_trip() -> None:
    intr = Intrinsics.from_fov(np.radians(60.0), np.radians(90.0), 518, 378)
    # Horizontal 90 degrees over 518 px: fx = 259 / tan(45 deg) = 259.
    assert intr.fx == pytest.approx(259.0)
    assert intr.cx == 259.0 and intr.cy == 189.0
    fov_h, fov_w = intr.fov()
    assert fov_h == pytest.approx(np.radians(60.0)) and fov_w == pytest.approx(np.radians(90.0))
    again = Intrinsics.from_matrix(intr.matrix(), 518, 378)
    assert again == intr


@pytest.mark.parametrize('bad', [{'fx': np.nan}, {'fx': -1.0}, {'width': 0}])
def test_intrinsics_reject_bad_values(bad: dict) -> None:
    values = {'fx': 500.0, 'fy': 500.0, 'cx': 10.0, 'cy': 10.0, 'width': 20, 'height': 20} | bad
    with pytest.raises(InputError, match='intrinsics'):
        Intrinsics(**values)


def test_intrinsics_coerce_numeric_fields() -> None:
    intr = Intrinsics(np.float32(500.0), 500, np.int64(320), 240.5, np.int32(640), 480.0)
    assert intr == Intrinsics(500.0, 500.0, 320.0, 240.5, 640, 480)
    assert [type(value) for value in (intr.fx, intr.fy, intr.cx, intr.cy)] == [float] * 4
    assert type(intr.width) is int and type(intr.height) is int
    assert Intrinsics.from_matrix(intr.matrix(), np.int64(640), 480) == intr


@pytest.mark.parametrize(('bad', 'message'), [
    ({'fx': '500'}, r"intrinsics fx: expected a number, got '500' \(str\)"),
    ({'cy': None}, r'intrinsics cy: expected a number, got None \(NoneType\)'),
    ({'fy': True}, r'intrinsics fy: expected a number, got True \(bool\)'),
    ({'cx': float('inf')}, 'intrinsics cx: got inf, which is NaN or infinite'),
    ({'fy': np.nan}, 'intrinsics fy: got nan, which is NaN or infinite'),
    ({'fy': 0}, 'focal lengths must be positive, got fx=500.0, fy=0.0'),
    ({'width': 640.5}, 'intrinsics width: image size must be a positive whole number of pixels, '
                       'got 640.5'),
    ({'height': -2}, 'intrinsics height: .* got -2'),
    ({'height': '480'}, "intrinsics height: .* got '480'"),
    ({'width': float('nan')}, 'intrinsics width: .* got nan'),
])
def test_intrinsics_name_the_bad_field(bad: dict, message: str) -> None:
    values = {'fx': 500.0, 'fy': 500.0, 'cx': 10.0, 'cy': 10.0, 'width': 640, 'height': 480}
    with pytest.raises(InputError, match=message):
        Intrinsics(**(values | bad))


def test_intrinsics_from_fov_checks_its_arguments() -> None:
    with pytest.raises(InputError, match="intrinsics fov_h_rad: expected a number, got '1'"):
        Intrinsics.from_fov('1', 1.0, 64, 48)
    with pytest.raises(InputError, match='intrinsics width: .* got 64.5'):
        Intrinsics.from_fov(1.0, 1.0, 64.5, 48)


def test_camera_pose_maps_points_and_quaternion(rng: np.random.Generator) -> None:
    rotation = geometry.axis_angle_to_matrix(rng.normal(size=3))
    pose = CameraPose(rotation, [1.0, 2.0, 3.0])
    point = rng.normal(size=3)
    np.testing.assert_allclose(pose.to_world(point), rotation @ point + [1, 2, 3])
    np.testing.assert_allclose(pose.inverse_matrix() @ pose.matrix(), np.eye(4), atol=1e-12)
    again = CameraPose.from_quaternion(pose.quaternion_xyzw(), pose.translation)
    np.testing.assert_allclose(again.rotation, rotation, atol=1e-12)


def test_camera_pose_rejects_non_rotations() -> None:
    with pytest.raises(InputError, match='not a proper rotation'):
        CameraPose(np.diag([1.0, 1.0, -1.0]), np.zeros(3))
    with pytest.raises(InputError, match='NaN'):
        CameraPose(np.eye(3), [0.0, np.nan, 0.0])
    with pytest.raises(InputError, match='zero quaternion'):
        CameraPose.from_quaternion(np.zeros(4), np.zeros(3))


def _hand(side: int) -> HandState:
    return HandState(side=side, mano_cam=ManoParams.zeros(), joints_cam=np.zeros((21, 3)),
                     joints_2d=np.zeros((21, 2)), box_xyxy=[0, 0, 10, 10], confidence=0.9)


def test_mano_params_and_hand_validation() -> None:
    with pytest.raises(InputError, match=r'MANO hand_pose: expected shape \(15, 3\)'):
        ManoParams(np.zeros(3), np.zeros(45), np.zeros(10), np.zeros(3))
    with pytest.raises(InputError, match='confidence'):
        HandState(side=0, mano_cam=ManoParams.zeros(), joints_cam=np.zeros((21, 3)),
                  joints_2d=np.zeros((21, 2)), box_xyxy=[0, 0, 1, 1], confidence=1.5)
    with pytest.raises(ValueError, match='hand side'):
        _hand(3)


def test_frame_result_finds_hands_and_rejects_duplicates() -> None:
    intr = Intrinsics(100.0, 100.0, 50.0, 50.0, 100, 100)
    frame = FrameResult(timestamp_ns=5, frame_index=0, camera_pose=CameraPose.identity(),
                        intrinsics=intr, hands=(_hand(1),))
    assert frame.hand(1) is not None and frame.hand(0) is None
    with pytest.raises(InputError, match='more than one hand per side'):
        FrameResult(timestamp_ns=5, frame_index=0, camera_pose=CameraPose.identity(),
                    intrinsics=intr, hands=(_hand(1), _hand(1)))
