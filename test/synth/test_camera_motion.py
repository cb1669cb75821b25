"""Head trajectory and intrinsics: smooth, egocentric, clear of obstacles, FoV in range."""

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import InputError
from infinihand_ros.synth.camera_motion import CameraMotionConfig
from infinihand_ros.synth.camera_motion import FOV_RANGE_DEG
from infinihand_ros.synth.camera_motion import look_at
from infinihand_ros.synth.camera_motion import look_at_hands
from infinihand_ros.synth.camera_motion import make_camera_trajectory
from infinihand_ros.synth.camera_motion import sample_camera_motion
from infinihand_ros.synth.camera_motion import sample_intrinsics
from infinihand_ros.synth.scene import make_scene
from infinihand_ros.synth.scene import Scene
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

FPS = 10.0
FRAMES = 150
SEEDS = range(6)


@pytest.fixture(scope='module')
def scene() -> Scene:
    return make_scene(np.random.default_rng(21))


@pytest.fixture(scope='module')
def motions(scene: Scene) -> list:
    return [sample_camera_motion(np.random.default_rng(seed), scene, FRAMES, FPS)
            for seed in SEEDS]


def _relative_angles_deg(rotations: np.ndarray, reference: np.ndarray) -> np.ndarray:
    relative = np.einsum('...ji,...jk->...ik', reference, rotations)
    return np.degrees(Rotation.from_matrix(relative).magnitude())


def test_poses_are_rigid_camera_to_world_transforms(motions: list) -> None:
    for motion in motions:
        poses = motion.T_world_cam
        assert poses.shape == (FRAMES, 4, 4)
        rotations = poses[:, :3, :3]
        np.testing.assert_allclose(np.einsum('tji,tjk->tik', rotations, rotations),
                                   np.broadcast_to(np.eye(3), rotations.shape), atol=1e-9)
        np.testing.assert_allclose(np.linalg.det(rotations), 1.0, atol=1e-9)
        np.testing.assert_array_equal(poses[:, 3], np.broadcast_to([0, 0, 0, 1], (FRAMES, 4)))


def test_motion_is_smooth_at_ten_fps(motions: list) -> None:
    for motion in motions:
        positions = motion.T_world_cam[:, :3, 3]
        rotations = motion.T_world_cam[:, :3, :3]
        steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
        assert steps.max() <= CameraMotionConfig().max_speed_mps / FPS + 0.005  # bob included
        assert np.linalg.norm(np.diff(positions, 2, axis=0), axis=1).max() < 0.01
        assert _relative_angles_deg(rotations[1:], rotations[:-1]).max() < 6.0
        turn_rates = np.diff(_relative_angles_deg(rotations, rotations[0]))
        assert np.abs(np.diff(turn_rates)).max() < 2.0  # no jumps in angular speed


def test_motion_spans_the_required_ranges(motions: list) -> None:
    for motion in motions:
        positions = motion.T_world_cam[:, :3, 3]
        path = np.linalg.norm(np.diff(positions, axis=0), axis=1).sum()
        assert 0.2 <= path <= 3.0
        rotations = motion.T_world_cam[:, :3, :3]
        assert 10.0 <= _relative_angles_deg(rotations, rotations[0]).max() <= 120.0


def test_long_sequences_stay_within_three_metres(scene: Scene) -> None:
    motion = sample_camera_motion(np.random.default_rng(1), scene, 1200, FPS)
    path = np.linalg.norm(np.diff(motion.T_world_cam[:, :3, 3], axis=0), axis=1).sum()
    assert 0.2 <= path <= 3.0


def test_camera_stands_at_eye_height_outside_obstacles(scene: Scene, motions: list) -> None:
    config = CameraMotionConfig()
    for motion in motions:
        eyes = motion.T_world_cam[:, :3, 3]
        assert np.all(scene.room.contains(eyes, -config.clearance_m))
        for box in scene.obstacles:
            assert not box.contains(eyes, config.clearance_m).any()
        low, high = config.eye_height_range_m
        assert np.all((eyes[:, 2] > low - 0.05) & (eyes[:, 2] < high + 0.05))


def test_camera_looks_down_at_the_table(scene: Scene, motions: list) -> None:
    k = sample_intrinsics(np.random.default_rng(0), fov_range_deg=(60.0, 60.0))
    table = scene.table
    for motion in motions:
        forward = motion.T_world_cam[:, :3, 2]
        pitch_down = np.degrees(np.arcsin(-forward[:, 2]))
        assert np.all((pitch_down > 20.0) & (pitch_down < 85.0))
        gaze = motion.gaze_world
        assert np.all(np.abs(gaze[:, :2] - table.center[:2]) <= table.half_extents[:2] + 1e-9)
        np.testing.assert_allclose(gaze[:, 2], scene.table_top_z)
        # The gaze point stays well inside even the narrowest image.
        rotations, eyes = motion.T_world_cam[:, :3, :3], motion.T_world_cam[:, :3, 3]
        in_cam = np.einsum('tji,tj->ti', rotations, gaze - eyes)
        pixels = in_cam[:, :2] / in_cam[:, 2:] * k[0, 0] + k[:2, 2]
        assert np.all(in_cam[:, 2] > 0.3)
        assert np.all((pixels > 0) & (pixels < [518, 378]))


def _palms(motion, down_m: np.ndarray, ahead_m: float = 0.35, side_m: float = 0.1) -> np.ndarray:
    """Palm positions (T, 3) fixed relative to the body's horizontal heading."""
    eyes = motion.T_world_cam[:, :3, 3]
    forward = motion.T_world_cam[:, :3, 2] * [1.0, 1.0, 0.0]
    forward /= np.linalg.norm(forward, axis=1, keepdims=True)
    left = np.cross([0.0, 0.0, 1.0], forward)
    return eyes + ahead_m * forward + side_m * left - down_m[:, None] * [0.0, 0.0, 1.0]


def _off_centre(poses: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Angle (degrees) between each camera's optical axis and the direction to its point."""
    rays = points - poses[:, :3, 3]
    cosine = np.sum(rays * poses[:, :3, 2], axis=1) / np.linalg.norm(rays, axis=1)
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def test_head_turns_towards_raised_hands_and_keeps_its_eyes(motions: list) -> None:
    for seed, motion in enumerate(motions):
        palms = _palms(motion, np.full(FRAMES, 0.3))
        poses = look_at_hands(np.random.default_rng(seed), motion, [palms], FPS)
        np.testing.assert_array_equal(poses[:, :3, 3], motion.T_world_cam[:, :3, 3])
        rotations = poses[:, :3, :3]
        np.testing.assert_allclose(np.einsum('tji,tjk->tik', rotations, rotations),
                                   np.broadcast_to(np.eye(3), rotations.shape), atol=1e-9)
        body, head = _off_centre(motion.T_world_cam, palms), _off_centre(poses, palms)
        assert np.all(head < body) and np.median(head) < 0.6 * np.median(body)


def test_hands_at_rest_leave_the_body_gaze(motions: list) -> None:
    for seed, motion in enumerate(motions):
        low = _palms(motion, np.full(FRAMES, 1.2))  # hanging by the body
        behind = _palms(motion, np.full(FRAMES, 0.3), ahead_m=-0.5)
        poses = look_at_hands(np.random.default_rng(seed), motion, [low, behind], FPS)
        np.testing.assert_allclose(poses, motion.T_world_cam, atol=1e-5)


def test_head_follows_hands_smoothly_as_they_rise_and_drop(motions: list) -> None:
    down = 0.625 + 0.375 * np.sin(np.pi * np.arange(FRAMES) / FPS)  # 0.25-1 m, 2 s period
    for seed, motion in enumerate(motions):
        poses = look_at_hands(np.random.default_rng(seed), motion, [_palms(motion, down)], FPS)
        rotations = poses[:, :3, :3]
        assert _relative_angles_deg(rotations[1:], rotations[:-1]).max() < 6.0
        steps = Rotation.from_matrix(rotations[1:] @ np.swapaxes(rotations[:-1], 1, 2))
        acceleration = np.linalg.norm(np.diff(steps.as_rotvec(), axis=0), axis=1)
        assert np.degrees(acceleration).max() < 2.0  # degrees per frame, per frame


def test_trajectory_is_deterministic_per_seed(scene: Scene) -> None:
    first = make_camera_trajectory(np.random.default_rng(5), scene, 30, FPS)
    again = make_camera_trajectory(np.random.default_rng(5), scene, 30, FPS)
    other = make_camera_trajectory(np.random.default_rng(6), scene, 30, FPS)
    np.testing.assert_array_equal(first, again)
    assert not np.allclose(first, other)
    assert make_camera_trajectory(np.random.default_rng(5), scene, 1, FPS).shape == (1, 4, 4)


def test_intrinsics_have_a_horizontal_fov_in_range_and_centred_principal_point() -> None:
    rng = np.random.default_rng(0)
    fovs = []
    for _ in range(200):
        k = sample_intrinsics(rng)
        assert k[0, 0] == k[1, 1]
        np.testing.assert_allclose(k[:2, 2], [259.0, 189.0])
        fovs.append(np.degrees(2.0 * np.arctan(259.0 / k[0, 0])))
    low, high = FOV_RANGE_DEG
    assert low <= min(fovs) and max(fovs) <= high
    assert max(fovs) - min(fovs) > 0.8 * (high - low)  # the range is actually used
    k = sample_intrinsics(rng, 100, 50, (90.0, 90.0))
    assert k[0, 0] == pytest.approx(50.0)


def test_look_at_builds_an_opencv_camera() -> None:
    rotation = look_at(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 1.0, 1.0]]))[0]
    np.testing.assert_allclose(rotation[:, 2], [0.0, 1.0, 0.0], atol=1e-12)  # z forward
    np.testing.assert_allclose(rotation[:, 1], [0.0, 0.0, -1.0], atol=1e-12)  # y down
    np.testing.assert_allclose(rotation[:, 0], [1.0, 0.0, 0.0], atol=1e-12)  # x right


def test_bad_arguments_raise_clear_errors(scene: Scene) -> None:
    with pytest.raises(InputError, match='num_frames must be >= 1'):
        make_camera_trajectory(np.random.default_rng(0), scene, 0, FPS)
    with pytest.raises(InputError, match='fps > 0'):
        make_camera_trajectory(np.random.default_rng(0), scene, 10, 0.0)
    with pytest.raises(InputError, match='fov_range_deg'):
        sample_intrinsics(np.random.default_rng(0), fov_range_deg=(100.0, 190.0))
    with pytest.raises(ConfigError, match='standoff_range_m'):
        CameraMotionConfig(standoff_range_m=(0.1, 0.3), max_depth_m=0.2)
