"""Tests of synth/gestures.py and of the articulation range of the synthetic hands."""

from infinihand_ros.eval import baselines
from infinihand_ros.eval.metrics import procrustes_error
from infinihand_ros.mano.mirror import mirror_axis_angle
from infinihand_ros.synth import gestures
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
from scipy.spatial.transform import Rotation


def test_zero_gesture_is_the_flat_hand() -> None:
    pose = gestures.gesture_hand_pose(np.zeros((2, 21)), side=1)
    assert pose.shape == (2, 15, 3) and np.count_nonzero(pose) == 0


def test_flexion_spread_and_opposition_turn_about_their_axes() -> None:
    """Index base: 30 deg spread (about y) then 60 deg flexion (z); thumb base: opposition."""
    vector = np.zeros(21)
    vector[3] = 60.0        # index, base joint flexion
    vector[16] = 30.0       # index spread
    vector[0] = 20.0        # thumb base flexion
    vector[20] = 45.0       # thumb opposition
    pose = gestures.gesture_hand_pose(vector[None], side=1)[0]
    index_base = Rotation.from_rotvec(pose[0])
    expected = (Rotation.from_rotvec(np.radians(30.0) * gestures.SPREAD_AXIS)
                * Rotation.from_rotvec(np.radians(60.0) * gestures.FINGER_FLEX_AXIS))
    assert (index_base * expected.inv()).magnitude() == pytest.approx(0.0, abs=1e-9)
    thumb_base = Rotation.from_rotvec(pose[12])  # MANO slot 4 (thumb), first joint
    expected = (Rotation.from_rotvec(np.radians(45.0) * gestures.OPPOSITION_AXIS)
                * Rotation.from_rotvec(np.radians(20.0) * gestures.THUMB_FLEX_AXIS))
    assert (thumb_base * expected.inv()).magnitude() == pytest.approx(0.0, abs=1e-9)
    assert np.count_nonzero(pose[[1, 2, 3, 4, 5, 13, 14]]) == 0


def test_left_hands_are_mirrored() -> None:
    vector = np.random.default_rng(1).uniform(0.0, 60.0, size=(3, 21))
    np.testing.assert_allclose(gestures.gesture_hand_pose(vector, side=0),
                               mirror_axis_angle(gestures.gesture_hand_pose(vector, side=1)))


@pytest.mark.parametrize('kind', [*gestures.GRASP_KINDS, *gestures.HOVER_KINDS, 'rest'])
def test_every_kind_draws_finite_bounded_angles(kind: str) -> None:
    rng = np.random.default_rng(2)
    for _ in range(20):
        vector = gestures.draw_gesture(rng, kind).as_vector()
        assert vector.shape == (21,) and np.isfinite(vector).all()
        assert vector[:15].max() <= 100.0 + 4 * gestures.FLEX_JITTER_DEG
        assert vector[:15].min() >= -5.0


def test_unknown_kind_is_refused() -> None:
    with pytest.raises(ValueError, match='unknown gesture kind'):
        gestures.draw_gesture(np.random.default_rng(0), 'wave')


def test_training_mean_pose_scores_at_least_12_mm_on_new_seeds() -> None:
    """Articulation worth learning: the mean pose of some seeds, on other seeds, PA >= 12 mm."""
    def tracks(seeds: range) -> list:
        return [(track, joints) for seed in seeds
                for sequence in [SyntheticSequence(SynthConfig(), seed, 100)]
                for track, joints in zip(sequence.tracks, sequence.joints_scene)]

    train = tracks(range(500, 506))
    mean = baselines.mean_articulation([t.hand_pose for t, _ in train],
                                       [t.side for t, _ in train])
    skeletons = baselines.mean_pose_joints(mean)
    errors = [procrustes_error(np.broadcast_to(skeletons[track.side], joints.shape).copy(), joints)
              for track, joints in tracks(range(900, 906))]
    assert float(np.concatenate(errors).mean()) * 1000.0 >= 12.0
