"""The whole-episode refinement: used only where it explains held-out tracks clearly better."""

from ba_builders import synth_keyframe
from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.config import EpisodeConfig
from infinihand_ros.ba.config import SolverConfig
from infinihand_ros.ba.episode import decrease_z
from infinihand_ros.ba.episode import EpisodeKeyframes
from infinihand_ros.ba.episode import judge
from infinihand_ros.ba.episode import refine_episode
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

EPISODE = EpisodeConfig(enabled=True)
#: Held-out observations of the judged examples: 100 tracks of 3 views.
TRACKS = np.repeat(np.arange(100), 3)


def test_judge_accepts_a_clear_gain_with_supported_moves(rng) -> None:
    """20 % lower held-out cost, far above its noise, and moves inside their bounds."""
    before = 1.0 + 0.1 * rng.standard_normal(len(TRACKS))
    accepted, reason = judge(before, 0.8 * before, TRACKS, np.full(4, 0.01), np.full(4, 0.02),
                             EPISODE)
    assert accepted, reason


@pytest.mark.parametrize('change, moves, words', [
    (0.0, 0.01, 'less than 5 %'),  # explains the held-out tracks no better
    (+0.3, 0.01, 'less than 5 %'),  # explains them worse
    (None, 0.01, 'standard errors'),  # 10 % lower on average, but as noise
    (-0.2, 0.05, 'the images support'),  # clearly better, but a keyframe moves too far
])
def test_judge_refuses_what_the_images_do_not_support(rng, change, moves, words) -> None:
    """Each way a refinement can fail to improve on the stream refuses it, saying which."""
    before = 1.0 + 0.1 * rng.standard_normal(len(TRACKS))
    if change is None:  # per-track changes of +-1 px^2 around a 0.1 decrease
        after = before - 0.1 + np.repeat(np.tile([-1.0, 1.0], 50), 3)
    else:
        after = before * (1.0 + change)
    accepted, reason = judge(before, after, TRACKS, np.array([0.0, 0.01, moves]),
                             np.full(3, 0.02), EPISODE)
    assert not accepted and words in reason


def test_too_few_held_out_observations_refuse_it() -> None:
    """Nothing to judge by: the stream's poses stand."""
    accepted, reason = judge(np.ones(5), np.zeros(5), np.arange(5), np.zeros(2), np.ones(2),
                             EPISODE)
    assert not accepted and 'held-out observations' in reason


def test_the_decrease_is_measured_against_the_spread_between_tracks() -> None:
    """The same decrease on every track is certain; one that differs per track is not."""
    track = np.repeat(np.arange(50), 2)
    assert decrease_z(np.ones(100), np.zeros(100), track) == np.inf
    noisy = np.where(track % 2 == 0, 1.5, -0.5)  # +-1 around a mean decrease of 0.5
    expected = 0.5 * np.sqrt(49)  # the mean over its standard error, 1 / sqrt(49)
    assert decrease_z(noisy, np.zeros(100), track) == pytest.approx(expected, rel=1e-6)


def test_the_kept_keyframes_stay_spread_over_the_episode() -> None:
    """Past the limit every other keyframe goes and then only every other one is kept."""
    kept = EpisodeKeyframes(4)
    for frame in range(10):
        kept.add(frame)
    assert kept.keyframes() == [0, 4, 8]
    with pytest.raises(ConfigError, match='max_keyframes'):
        EpisodeConfig(max_keyframes=1)


@pytest.fixture(scope='module')
def keyframes() -> list:
    """Return 6 keyframes of a synthetic sequence (true poses and depth)."""
    sequence = SyntheticSequence(SynthConfig(width=320, height=240), seed=3, num_frames=12)
    return [synth_keyframe(sequence.frame(index)) for index in range(0, 12, 2)]


def _drifted(poses: np.ndarray, degrees_per_frame: float) -> np.ndarray:
    """Return poses (K, 4, 4) turned about y by ``degrees_per_frame`` more at each keyframe."""
    out = poses.copy()
    for index in range(1, len(out)):
        turn = Rotation.from_rotvec([0.0, np.radians(degrees_per_frame * index), 0.0])
        out[index, :3, :3] = turn.as_matrix() @ out[index, :3, :3]
    return out


def test_a_drifted_start_is_refined_and_a_true_one_stands(keyframes: list) -> None:
    """From drifted poses it is accepted and nearer the truth; from the truth it is refused."""
    config = BAConfig(solver=SolverConfig(rel_pose_sigma_m=0.0), episode=EPISODE)
    truth = np.stack([keyframe.T_world_cam for keyframe in keyframes])
    drifted = _drifted(truth, 0.5)
    refined = refine_episode(keyframes, drifted, None, config)
    assert refined.accepted, refined.reason
    assert refined.refined_cost < refined.initial_cost
    error_before = np.linalg.norm(drifted[:, :3, :3] - truth[:, :3, :3])
    assert np.linalg.norm(refined.T_refined[:, :3, :3] - truth[:, :3, :3]) < 0.5 * error_before
    standing = refine_episode(keyframes, truth, None, config)
    assert not standing.accepted, standing.reason
    np.testing.assert_array_equal(standing.T_start, truth)
