"""Hand orientations of the synthetic motion: each hand continues its forearm."""

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.synth import arms
from infinihand_ros.synth import hand_motion
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest

AXIS = np.array([1.0, 0.0, 0.0])
PALM_DOWN = np.array([0.0, 0.0, -1.0])
INWARDS = np.array([0.0, 1.0, 0.0])


def _fingers_and_normal(side: int, rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Finger direction and palm normal of a hand rotation (canonical x = -fingers, y = -palm)."""
    fingers = rotation[:, 0] if side == LEFT else -rotation[:, 0]
    return fingers, -rotation[:, 1]


@pytest.mark.parametrize('side', [LEFT, RIGHT])
def test_wrist_angles_turn_the_hand_about_its_forearm(side: int) -> None:
    forearm = (AXIS, PALM_DOWN, INWARDS)
    fingers, normal = _fingers_and_normal(side, hand_motion._wrist_pose(side, forearm, 0, 0, 0))
    np.testing.assert_allclose(fingers, AXIS, atol=1e-12)
    np.testing.assert_allclose(normal, PALM_DOWN, atol=1e-12)
    rotation = hand_motion._wrist_pose(side, forearm, np.pi / 2, 0, 0)
    np.testing.assert_allclose(_fingers_and_normal(side, rotation)[1], INWARDS, atol=1e-12)
    fingers, normal = _fingers_and_normal(
        side, hand_motion._wrist_pose(side, forearm, 0, np.radians(30), 0))
    np.testing.assert_allclose(fingers, [np.cos(np.radians(30)), 0, np.sin(np.radians(30))],
                               atol=1e-12)  # extension lifts the fingers off the palm side
    np.testing.assert_allclose(normal @ fingers, 0, atol=1e-12)
    for rotation in (rotation, hand_motion._wrist_pose(side, forearm, 0.3, -0.2, 0.25)):
        np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)
        assert np.linalg.det(rotation) == pytest.approx(1.0)


def test_forearm_frame_points_inwards_for_each_side() -> None:
    style = arms.sample_arm_style(np.random.default_rng(0))
    T_world_cam = np.eye(4)
    T_world_cam[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # looking along +x, z up
    T_world_cam[:3, 3] = [0, 0, 1.5]
    for side, inward_y in ((LEFT, -1.0), (RIGHT, 1.0)):  # left of a +x-facing head is +y
        wrist = np.array([0.35, -inward_y * 0.15, 1.2])
        axis, palm_down, inwards = hand_motion._forearm_frame(wrist, T_world_cam, side, style)
        elbow = arms.arm_points(wrist, T_world_cam, side, style)[2]
        np.testing.assert_allclose(axis, (wrist - elbow) / np.linalg.norm(wrist - elbow))
        assert palm_down[2] < 0 and inwards[1] * inward_y > 0
        np.testing.assert_allclose([axis @ palm_down, axis @ inwards, palm_down @ inwards], 0,
                                   atol=1e-12)


def test_hands_in_sequences_continue_their_forearms() -> None:
    angles = []
    for seed in range(4):
        sequence = SyntheticSequence(SynthConfig(width=336, height=252), seed=seed,
                                     num_frames=90)
        for track, joints in zip(sequence.tracks, sequence.joints_scene):
            for index in range(0, 90, 3):
                wrist, _, elbow, _ = arms.arm_points(joints[index][0],
                                                     sequence.T_scene_body[index], track.side,
                                                     sequence.arm_style)
                forearm = (wrist - elbow) / np.linalg.norm(wrist - elbow)
                fingers = joints[index][9] - joints[index][0]  # wrist to middle knuckle
                cosine = forearm @ fingers / np.linalg.norm(fingers)
                angles.append(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))
    assert np.median(angles) < 25.0 and np.percentile(angles, 95) < 45.0
