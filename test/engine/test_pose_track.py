"""Tests of engine/pose_track.py: one scale for the whole track, smooth refinements, versions."""

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.geometry import invert_transform
from infinihand_ros.core.geometry import make_transform
from infinihand_ros.engine.metric_scale import MetricScaleConfig
from infinihand_ros.engine.pose_track import PoseTrack
from infinihand_ros.engine.pose_track import PoseTrackConfig
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

SCALE = MetricScaleConfig(history=50, min_samples=3)


def _pose(x: float) -> np.ndarray:
    transform = np.eye(4)
    transform[0, 3] = x
    return transform


def _observe(track: PoseTrack, ratio: float, count: int = 1) -> None:
    track.observe_scale(np.full(count, ratio), np.ones(count))


def test_warm_up_keeps_the_initial_scale_then_rescales_the_whole_track() -> None:
    """Until min_samples the scale is 1; then every frame, old ones too, gets the estimate."""
    track = PoseTrack(PoseTrackConfig(), SCALE)
    for index in range(4):
        track.add(index, index * 10, _pose(float(index)))
    _observe(track, 0.1, count=2)
    assert track.scale_state == 'warmup' and track.scale == 1.0 and track.version == 0
    assert track.best(3).camera_pose.translation[0] == pytest.approx(3.0)
    _observe(track, 0.1)
    assert track.scale_state == 'tracking' and track.scale == pytest.approx(0.1)
    assert track.version == 1
    for index in range(4):
        assert track.best(index).camera_pose.translation[0] == pytest.approx(0.1 * index)
        assert track.best(index).version == 1


def test_later_refinements_are_bounded_per_frame_and_ignore_noise() -> None:
    """After the warm-up the applied scale moves at most max_scale_step per observation."""
    config = PoseTrackConfig(max_scale_step=0.01, scale_deadband=0.002)
    track = PoseTrack(config, MetricScaleConfig(history=5, min_samples=3))
    _observe(track, 1.0, count=3)
    assert track.scale == pytest.approx(1.0)
    version = track.version
    _observe(track, 1.001)  # median still 1.0: no change, no new version
    assert track.version == version
    scales = []
    for _ in range(10):
        _observe(track, 2.0)
        scales.append(track.scale)
    steps = np.diff([1.0] + scales) / np.array([1.0] + scales[:-1])
    assert np.all(steps <= 0.01 + 1e-12) and scales[-1] > 1.05
    changes = int(np.count_nonzero(np.diff([1.0] + scales)))
    assert changes >= 5 and track.version == version + changes


def test_the_world_is_re_anchored_to_the_first_frame() -> None:
    """Network poses G T_t (any G) give the track T_0^-1 T_t: first pose exactly the identity."""
    rng = np.random.default_rng(3)
    offset = make_transform(Rotation.from_rotvec(rng.normal(size=3)).as_matrix(),
                            rng.normal(size=3))
    poses = [make_transform(Rotation.from_rotvec(0.1 * rng.normal(size=3)).as_matrix(),
                            rng.normal(size=3)) for _ in range(4)]
    track = PoseTrack(PoseTrackConfig(), SCALE)
    for index, pose in enumerate(poses):
        track.add(index, index, offset @ pose)
    np.testing.assert_allclose(track.best(0).camera_pose.matrix(), np.eye(4), atol=1e-12)
    for index, pose in enumerate(poses):
        np.testing.assert_allclose(track.best(index).camera_pose.matrix(),
                                   invert_transform(poses[0]) @ pose, atol=1e-9)


def test_track_memory_is_bounded() -> None:
    """Only the newest ``capacity`` frames are kept."""
    track = PoseTrack(PoseTrackConfig(capacity=5), SCALE)
    for index in range(100):
        track.add(index, index, _pose(0.0))
    track.best(99)
    with pytest.raises(KeyError):
        track.best(94)


def test_ba_corrections_change_the_best_pose_and_the_version() -> None:
    """A BA update moves the best pose onto the refined one; the scaled pose stays raw."""
    track = PoseTrack(PoseTrackConfig(), SCALE, blend_s=0.0)
    for index in range(3):
        track.add(index, index * 100, _pose(float(index)))
    refined = np.stack([_pose(index + 0.5) for index in range(3)])
    raw = np.stack([_pose(float(index)) for index in range(3)])
    track.update_corrections(np.array([0, 100, 200]), refined, raw)
    best = track.best(2, live=False)
    assert best.version == 1
    np.testing.assert_allclose(best.camera_pose.translation, [2.5, 0, 0], atol=1e-9)
    np.testing.assert_allclose(best.scaled_pose.translation, [2.0, 0, 0])


def test_config_rejects_bad_values() -> None:
    """Capacity, step and deadband are checked with the key named."""
    with pytest.raises(ConfigError, match='pose_track.capacity'):
        PoseTrackConfig(capacity=0)
    with pytest.raises(ConfigError, match='scale_deadband < max_scale_step'):
        PoseTrackConfig(max_scale_step=0.01, scale_deadband=0.02)


def test_a_ba_correction_stays_right_when_the_scale_moves_afterwards() -> None:
    """BA at scale 2 put frame 1 at x = 3 m (raw 1 unit); at scale 3 it is at x = 4.5 m.

    Corrections are kept in model units, so the refined pose scales with the trajectory.
    """
    track = PoseTrack(PoseTrackConfig(max_scale_step=0.5, scale_deadband=0.01), SCALE)
    track.add(0, 0, _pose(0.0))
    track.add(1, 100, _pose(1.0))
    _observe(track, 2.0, count=3)
    assert track.scale == pytest.approx(2.0)
    track.update_corrections(np.array([0, 100]), np.stack([_pose(0.0), _pose(3.0)]),
                             np.stack([_pose(0.0), _pose(2.0)]), scale=2.0)
    assert track.best(1, live=False).camera_pose.translation[0] == pytest.approx(3.0)
    _observe(track, 6.0, count=50)  # the scale steps 50 % towards the new estimate
    assert track.scale == pytest.approx(3.0)
    assert track.best(1, live=False).camera_pose.translation[0] == pytest.approx(4.5)
