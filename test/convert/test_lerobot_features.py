"""Tests of infinihand_ros/convert/lerobot_features.py: names, state layout, invalid hands."""

from infinihand_ros.convert import lerobot_features as features
from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.wrist_frame import keypoints_in_wrist_frame
import numpy as np


def _right_hand(rng: np.random.Generator) -> HandState:
    mano = ManoParams(rng.normal(size=3), rng.normal(size=(15, 3)), rng.normal(size=10),
                      rng.normal(size=3))
    return HandState(RIGHT, mano, rng.normal(size=(21, 3)), np.zeros((21, 2)), np.zeros(4), 0.8,
                     mano_world=mano, joints_world=rng.normal(size=(21, 3)))


def _spec(key: str) -> features.FeatureSpec:
    return next(spec for spec in features.FRAME_FEATURES if spec.key == key)


def test_every_dimension_is_named_uniquely() -> None:
    """Each feature has one unique name per dimension; LeRobot names hold no '/'."""
    for spec in features.FRAME_FEATURES:
        assert len(set(spec.names)) == len(spec.names), spec.key
        assert '/' not in spec.key
    assert _spec(features.STATE).shape == (48,)
    assert _spec(features.STATE).names[:3] == ('left_wrist_x', 'left_wrist_y', 'left_wrist_z')
    assert _spec(features.STATE).names[24] == 'right_wrist_x'
    assert _spec(features.KEYPOINTS_WORLD).names[-1] == 'right_pinky_tip_z'


def test_values_of_a_right_hand_and_a_missing_left(rng: np.random.Generator) -> None:
    """The right half holds the hand (state = wrist, rot6d, tips); the left is flagged."""
    hand = _right_hand(rng)
    pose = CameraPose(geometry.axis_angle_to_matrix(rng.normal(size=3)), rng.normal(size=3))
    result = FrameResult(5, 0, pose, Intrinsics(100, 101, 80, 60, 160, 120), (hand,))
    values, reasons = features.frame_values(result, fill=-7.0)
    assert reasons == {'left': features.NOT_DETECTED}
    assert values[features.HAND_VALID].tolist() == [0.0, 1.0]
    assert values[features.HAND_CONFIDENCE].tolist() == [0.0, 0.8]
    state = values[features.STATE]
    assert np.all(state[:24] == -7.0)
    rotation = geometry.axis_angle_to_matrix(hand.mano_world.global_orient)
    np.testing.assert_allclose(state[24:27], hand.joints_world[0])
    np.testing.assert_allclose(state[27:33], np.concatenate([rotation[:, 0], rotation[:, 1]]))
    np.testing.assert_allclose(state[33:36], hand.joints_world[4])  # thumb tip
    np.testing.assert_allclose(state[-3:], hand.joints_world[20])  # pinky tip
    wrist, _ = keypoints_in_wrist_frame(hand.joints_world, RIGHT)
    np.testing.assert_allclose(values[features.KEYPOINTS_WRIST][63:], wrist.reshape(-1))
    np.testing.assert_allclose(values[features.CAMERA_POSE], pose.matrix().reshape(-1))
    assert values[features.INTRINSICS].tolist() == [100, 101, 80, 60]
    for key in features.RESULT_FEATURES:
        assert values[key].shape == _spec(key).shape, key


def test_hand_without_world_pose_is_invalid(rng: np.random.Generator) -> None:
    """A detected hand that was not placed in the world is invalid, its confidence kept."""
    hand = _right_hand(rng)
    camera_only = HandState(RIGHT, hand.mano_cam, hand.joints_cam, hand.joints_2d,
                            hand.box_xyxy, 0.6)
    result = FrameResult(5, 0, CameraPose.identity(), Intrinsics(1, 1, 0, 0, 2, 2),
                         (camera_only,))
    values, reasons = features.frame_values(result, fill=float('nan'))
    assert reasons['right'] == features.NOT_IN_WORLD
    assert values[features.HAND_CONFIDENCE].tolist() == [0.0, 0.6]
    assert np.isnan(values[features.KEYPOINTS_WORLD]).all()


def test_camera_flags_mark_keyframes_ba_corrections_and_tracking() -> None:
    """``camera.flags``: keyframe, BA correction, measured pose, track restart, BA failure.

    keyframe as the engine said; ba_corrected only when BA moved the pose; tracked when the
    pose was measured (or the camera is fixed); reinitialised where the track restarted;
    ba_failed where the frame's last BA call failed; episode_refined where the pose carries
    the whole-episode refinement.
    """
    intrinsics = Intrinsics(1, 1, 0, 0, 2, 2)
    moved = CameraPose(np.eye(3), np.array([0.0, 0.0, 0.01]))
    cases = [(FrameResult(1, 0, CameraPose.identity(), intrinsics), [0, 0, 0, 0, 0, 0]),
             (FrameResult(1, 0, moved, intrinsics, is_keyframe=True,
                          raw_camera_pose=moved, tracking='tracked'), [1, 0, 1, 0, 0, 0]),
             (FrameResult(1, 0, moved, intrinsics, raw_camera_pose=CameraPose.identity(),
                          tracking='reinitialised'), [0, 1, 0, 1, 0, 0]),
             (FrameResult(1, 0, moved, intrinsics, tracking='static'), [0, 0, 1, 0, 0, 0]),
             (FrameResult(1, 0, moved, intrinsics, is_keyframe=True, raw_camera_pose=moved,
                          tracking='tracked', ba_failed=True), [1, 0, 1, 0, 1, 0]),
             (FrameResult(1, 0, moved, intrinsics, raw_camera_pose=CameraPose.identity(),
                          episode_refined=True), [0, 1, 0, 0, 0, 1])]
    for result, flags in cases:
        values, _ = features.frame_values(result, fill=0.0)
        assert values[features.CAMERA_FLAGS].tolist() == flags
    assert _spec(features.CAMERA_FLAGS).names == ('keyframe', 'ba_corrected', 'tracked',
                                                  'reinitialised', 'ba_failed',
                                                  'episode_refined')
