"""Builders of random core results and equality checks shared by the bag tests."""

from infinihand_ros.bag.messages import KeyframePoseUpdate
from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import RIGHT
import numpy as np
import pytest

#: A realistic stamp (2026-01-01T00:00:00.123456789Z) in nanoseconds.
BASE_STAMP_NS = 1_767_225_600_123_456_789
FRAME_PERIOD_NS = 33_333_333
IMAGE_WIDTH = 518
IMAGE_HEIGHT = 378


def random_pose(rng: np.random.Generator) -> CameraPose:
    """Return a random camera-to-world pose."""
    return CameraPose(geometry.axis_angle_to_matrix(rng.normal(size=3)), rng.normal(size=3))


def random_mano(rng: np.random.Generator) -> ManoParams:
    """Return random MANO parameters."""
    return ManoParams(rng.normal(size=3), rng.normal(scale=0.3, size=(NUM_HAND_POSE_JOINTS, 3)),
                      rng.normal(size=NUM_BETAS), rng.normal(scale=0.5, size=3))


def random_hand(rng: np.random.Generator, side: int, with_world: bool) -> HandState:
    """Return a random hand, with world-frame fields when ``with_world``."""
    return HandState(
        side=side,
        mano_cam=random_mano(rng),
        joints_cam=rng.normal(size=(NUM_JOINTS, 3)),
        joints_2d=rng.uniform(0.0, IMAGE_WIDTH, size=(NUM_JOINTS, 2)),
        box_xyxy=np.sort(rng.uniform(0.0, IMAGE_HEIGHT, size=4)),
        confidence=float(rng.uniform()),
        mano_world=random_mano(rng) if with_world else None,
        joints_world=rng.normal(size=(NUM_JOINTS, 3)) if with_world else None)


def random_frame(rng: np.random.Generator, frame_index: int = 7) -> FrameResult:
    """Return a random frame with a left hand (world fields set) and a right hand (camera only)."""
    return FrameResult(
        timestamp_ns=BASE_STAMP_NS + frame_index * FRAME_PERIOD_NS,
        frame_index=frame_index,
        camera_pose=random_pose(rng),
        intrinsics=Intrinsics(
            *rng.uniform(200.0, 400.0, size=4), width=IMAGE_WIDTH, height=IMAGE_HEIGHT),
        hands=(random_hand(rng, LEFT, with_world=True), random_hand(rng, RIGHT, with_world=False)),
        is_keyframe=bool(frame_index % 2),
        metric_scale=float(rng.uniform(0.5, 2.0)),
        tracking=('tracked', 'predicted', 'reinitialised', 'static')[frame_index % 4],
        provisional_intrinsics=frame_index % 3 == 0)


def random_keyframes(rng: np.random.Generator, count: int = 3) -> KeyframePoseUpdate:
    """Return a random bundle-adjustment update of ``count`` keyframes."""
    indices = tuple(int(i) for i in np.sort(rng.choice(1000, size=count, replace=False)))
    return KeyframePoseUpdate(
        frame_indices=indices,
        stamps_ns=tuple(BASE_STAMP_NS + i * FRAME_PERIOD_NS for i in indices),
        poses=tuple(random_pose(rng) for _ in range(count)),
        initial_cost=float(rng.uniform(10.0, 20.0)),
        final_cost=float(rng.uniform(0.0, 10.0)),
        num_iterations=12,
        converged=True)


def assert_mano_equal(got: ManoParams, want: ManoParams) -> None:
    """Check MANO parameters are bit-identical (float64 fields)."""
    for name in ('global_orient', 'hand_pose', 'betas', 'transl'):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)


def assert_pose_close(got: CameraPose, want: CameraPose) -> None:
    """Check poses agree: exact translation, rotation through a quaternion to 1e-12."""
    np.testing.assert_array_equal(got.translation, want.translation)
    np.testing.assert_allclose(got.rotation, want.rotation, atol=1e-12)


def assert_hand_equal(got: HandState, want: HandState) -> None:
    """Check hands agree: float64 fields exactly, float32 fields to float32 precision."""
    assert got.side == want.side
    assert got.confidence == pytest.approx(want.confidence, rel=1e-7)
    assert_mano_equal(got.mano_cam, want.mano_cam)
    np.testing.assert_array_equal(got.joints_cam, want.joints_cam)
    np.testing.assert_array_equal(got.joints_2d, want.joints_2d.astype(np.float32))
    np.testing.assert_array_equal(got.box_xyxy, want.box_xyxy.astype(np.float32))
    assert (got.mano_world is None) == (want.mano_world is None)
    assert (got.joints_world is None) == (want.joints_world is None)
    if want.mano_world is not None:
        assert_mano_equal(got.mano_world, want.mano_world)
        np.testing.assert_array_equal(got.joints_world, want.joints_world)


def assert_frame_equal(got: FrameResult, want: FrameResult) -> None:
    """Check a decoded frame equals the original (depth is not carried by HandFrame)."""
    assert got.timestamp_ns == want.timestamp_ns
    assert got.frame_index == want.frame_index
    assert got.is_keyframe == want.is_keyframe
    assert got.metric_scale == want.metric_scale
    assert got.intrinsics == want.intrinsics
    assert got.tracking == want.tracking
    assert got.provisional_intrinsics == want.provisional_intrinsics
    assert_pose_close(got.camera_pose, want.camera_pose)
    assert len(got.hands) == len(want.hands)
    for got_hand, want_hand in zip(got.hands, want.hands):
        assert_hand_equal(got_hand, want_hand)


def assert_keyframes_equal(got: KeyframePoseUpdate, want: KeyframePoseUpdate) -> None:
    """Check a decoded keyframe update equals the original."""
    assert got.frame_indices == want.frame_indices
    assert got.stamps_ns == want.stamps_ns
    assert (got.initial_cost, got.final_cost) == (want.initial_cost, want.final_cost)
    assert (got.num_iterations, got.converged) == (want.num_iterations, want.converged)
    assert len(got.poses) == len(want.poses)
    for got_pose, want_pose in zip(got.poses, want.poses):
        assert_pose_close(got_pose, want_pose)
