"""Tests of engine/world_placement.py against the numpy reference of eq. 9."""

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.mano_frames import transform_mano_params
from infinihand_ros.engine.world_placement import place_in_world
import numpy as np
from scipy.spatial.transform import Rotation


def _hand(rng: np.random.Generator, side: int) -> HandState:
    mano = ManoParams(rng.normal(size=3), rng.normal(size=(15, 3)) * 0.1, rng.normal(size=10),
                      rng.normal(size=3))
    joints = rng.normal(size=(21, 3))
    joints[0] = mano.transl + np.array([0.01, -0.02, 0.03])  # rest root J0 = (0.01, -0.02, 0.03)
    return HandState(side, mano, joints, rng.normal(size=(21, 2)), np.array([0, 0, 5, 5.0]), 0.9)


def test_hands_land_where_the_reference_puts_them() -> None:
    """Joints by the rigid pose, MANO params as core/mano_frames (root joint included)."""
    rng = np.random.default_rng(3)
    pose = CameraPose(Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix(), [1.0, 2.0, -0.5])
    hands = (_hand(rng, 0), _hand(rng, 1))
    placed = place_in_world(hands, pose)
    for hand, world in zip(hands, placed):
        np.testing.assert_allclose(world.joints_world,
                                   hand.joints_cam @ pose.rotation.T + pose.translation)
        reference = transform_mano_params(hand.mano_cam, pose.rotation, pose.translation,
                                          hand.joints_cam[0] - hand.mano_cam.transl)
        np.testing.assert_allclose(world.mano_world.global_orient, reference.global_orient,
                                   atol=1e-10)
        np.testing.assert_allclose(world.mano_world.transl, reference.transl, atol=1e-10)
        np.testing.assert_array_equal(world.mano_world.hand_pose, hand.mano_cam.hand_pose)


def test_no_hands_give_no_hands() -> None:
    """An empty frame stays empty."""
    assert place_in_world((), CameraPose.identity()) == ()
