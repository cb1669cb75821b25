"""The per-frame camera tracker on textured planes with exactly known cameras.

A textured plane at depth 2 in the first camera's frame is rendered by homography for any camera
pose, with its exact depth map, so every frame's true pose is known. The network's pose (the
tracker's prior) is the true pose with a rotation error that grows with time (drift).
"""

import cv2
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.geometry import make_transform
from infinihand_ros.engine.camera_tracker import CameraTracker
from infinihand_ros.engine.camera_tracker import TrackerConfig
from infinihand_ros.engine.camera_tracker import TrackingView
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

WIDTH, HEIGHT = 336, 252
K = Intrinsics(300.0, 300.0, WIDTH / 2 - 0.5, HEIGHT / 2 - 0.5, WIDTH, HEIGHT)
PLANE_DEPTH = 2.0
TEXTURE_K = np.array([[400.0, 0.0, 400.0], [0.0, 400.0, 300.0], [0.0, 0.0, 1.0]])


def texture(seed: int) -> np.ndarray:
    """Return an 800 x 600 grey texture: smoothed noise and random discs (trackable corners)."""
    rng = np.random.default_rng(seed)
    image = cv2.GaussianBlur(rng.uniform(0, 255, (600, 800)).astype(np.float32), (0, 0), 3)
    image = cv2.normalize(image, None, 0, 255, cv2.NORM_MINMAX)
    for _ in range(150):
        centre = (int(rng.integers(0, 800)), int(rng.integers(0, 600)))
        cv2.circle(image, centre, int(rng.integers(3, 12)), float(rng.uniform(0, 255)), -1)
    return image.astype(np.uint8)


def render(source: np.ndarray, T_world_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the grey image and depth of the plane z = PLANE_DEPTH seen from a camera pose."""
    rotation, translation = T_world_cam[:3, :3], T_world_cam[:3, 3]
    normal = rotation.T @ np.array([0.0, 0.0, 1.0])  # the plane in the camera: n.x = d
    distance = PLANE_DEPTH - translation[2]
    # camera pixel -> world point on the plane -> texture pixel (the texture seen from the origin)
    homography = TEXTURE_K @ (rotation + np.outer(translation, normal) / distance) \
        @ np.linalg.inv(K.matrix())
    gray = cv2.warpPerspective(source, homography, (WIDTH, HEIGHT),
                               flags=cv2.WARP_INVERSE_MAP | cv2.INTER_LINEAR)
    u, v = np.meshgrid(np.arange(WIDTH), np.arange(HEIGHT))
    rays = np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones(u.shape)], axis=-1)
    return gray, (distance / (rays @ normal)).astype(np.float32)


def view(gray: np.ndarray, depth: np.ndarray | None,
         boxes: np.ndarray | None = None) -> TrackingView:
    """Return the tracker's view of a frame (``depth`` None: a frame without the network)."""
    return TrackingView(gray, None if depth is None else (lambda: depth), K,
                        (0, 0, WIDTH, HEIGHT), np.zeros((0, 4)) if boxes is None else boxes)


def true_pose(index: int) -> np.ndarray:
    """Return a smooth camera path: about 24 degrees and 0.25 units over 60 frames."""
    angles = np.array([0.15, 0.3, 0.1]) * np.sin(index / 30.0)
    return make_transform(Rotation.from_euler('xyz', angles).as_matrix(),
                          np.array([0.004, -0.002, 0.003]) * index)


def pan(index: int) -> np.ndarray:
    """Return a panning camera path: about 29 degrees of yaw and 0.8 units over 120 frames."""
    angles = np.array([0.05, 0.5, 0.05]) * np.sin(index / 40.0)
    return make_transform(Rotation.from_euler('xyz', angles).as_matrix(),
                          np.array([0.006, -0.002, 0.002]) * index)


def drifting_network(index: int) -> np.ndarray:
    """Return the true pose with a rotation error growing by 0.3 degrees per frame."""
    drift = Rotation.from_rotvec(np.radians([0.0, 0.3 * index, 0.1 * index])).as_matrix()
    return true_pose(index) @ make_transform(drift, np.zeros(3))


def errors(T_estimate: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """Return (translation error, rotation error in degrees)."""
    angle = Rotation.from_matrix(T_estimate[:3, :3] @ T_true[:3, :3].T).magnitude()
    return float(np.linalg.norm(T_estimate[:3, 3] - T_true[:3, 3])), float(np.degrees(angle))


def test_tracks_a_moving_camera_where_the_network_drifts() -> None:
    """60 frames: within 0.5 degree and 0.5 % of the scene depth of the truth (network: 18 deg)."""
    source = texture(0)
    tracker = CameraTracker(TrackerConfig())
    for index in range(60):
        gray, depth = render(source, true_pose(index))
        result = tracker.track(view(gray, depth), drifting_network(index))
        assert result.state == 'tracked'
        translation_error, rotation_error = errors(result.T_raw, true_pose(index))
        assert rotation_error < 0.5 and translation_error < 0.005 * PLANE_DEPTH, index
    assert errors(drifting_network(59), true_pose(59))[1] > 15.0
    assert tracker.statistics()['states'] == {'tracked': 60}


def test_a_static_camera_stays_put_while_a_hand_moves() -> None:
    """A textured patch crossing the image inside its hand box moves no pose."""
    source = texture(1)
    patch = texture(2)[:80, :60]
    tracker = CameraTracker(TrackerConfig())
    background, depth = render(source, np.eye(4))
    for index in range(40):
        gray = background.copy()
        x0, y0 = 20 + 6 * index, 60 + (index % 7) * 4
        gray[y0:y0 + 80, x0:x0 + 60] = patch
        box = np.array([[x0, y0, x0 + 59, y0 + 79]], dtype=np.float64)
        network = make_transform(Rotation.from_rotvec([0.0, 0.01 * index, 0.0]).as_matrix(),
                                 np.array([0.01 * index, 0.0, 0.0]))
        result = tracker.track(view(gray, depth, box), network)
        translation_error, rotation_error = errors(result.T_raw, np.eye(4))
        assert result.state == 'tracked'
        assert translation_error < 1e-3 and rotation_error < 0.05, index


def test_textureless_frames_fall_back_to_the_network_then_tracking_resumes() -> None:
    source = texture(3)
    tracker = CameraTracker(TrackerConfig())
    states = []
    for index in range(30):
        gray, depth = render(source, true_pose(index))
        if 10 <= index < 14:  # the lens covered
            gray = np.full_like(gray, 90)
        result = tracker.track(view(gray, depth), true_pose(index))
        states.append(result.state)
        if result.state == 'predicted':  # the network's motion since the last frame
            np.testing.assert_allclose(result.T_raw, true_pose(index), atol=0.02)
    assert states[10:14] == ['predicted'] * 4
    assert states[15:] == ['tracked'] * 15
    assert errors(result.T_raw, true_pose(29))[1] < 1.0


def test_a_cut_to_another_scene_reinitialises_the_track_once() -> None:
    first, second = texture(4), texture(5)
    tracker = CameraTracker(TrackerConfig())
    states = []
    for index in range(20):
        gray, depth = render(first if index < 10 else second, true_pose(index))
        states.append(tracker.track(view(gray, depth), true_pose(index)).state)
    assert states[10] == 'reinitialised'
    assert states.count('reinitialised') == 1
    assert states[11:] == ['tracked'] * 9


def test_a_blurred_frame_is_bridged_from_the_last_sharp_one() -> None:
    source = texture(6)
    tracker = CameraTracker(TrackerConfig())
    for index in range(20):
        gray, depth = render(source, true_pose(index))
        if index == 8:
            gray = cv2.blur(gray, (25, 1))  # a fast horizontal pan
        result = tracker.track(view(gray, depth), drifting_network(index))
        if index != 8:
            assert result.state == 'tracked', index
    assert errors(result.T_raw, true_pose(19))[1] < 1.0


def test_disabled_or_without_image_gives_the_network_pose() -> None:
    tracker = CameraTracker(TrackerConfig(enabled=False))
    source = texture(7)
    for index in range(5):
        gray, depth = render(source, true_pose(index))
        result = tracker.track(view(gray, depth), drifting_network(index))
        np.testing.assert_allclose(result.T_raw, drifting_network(index), atol=1e-12)
        assert result.state == 'predicted'
    assert CameraTracker(TrackerConfig()).track(None, np.eye(4)).state == 'predicted'


def test_reset_starts_a_new_world() -> None:
    tracker = CameraTracker(TrackerConfig())
    source = texture(8)
    for index in range(5):
        tracker.track(view(*render(source, true_pose(index))), true_pose(index))
    tracker.reset()
    assert tracker.statistics() == {'states': {}, 'ms_per_frame': 0.0}
    result = tracker.track(view(*render(source, true_pose(3))), np.eye(4))
    np.testing.assert_allclose(result.T_raw, np.eye(4))


@pytest.mark.parametrize('settings, key', [
    ({'klt_window_px': 20}, 'klt_window_px'), ({'min_inliers': 3}, 'min_inliers'),
    ({'cut_fraction': 1.0}, 'cut_fraction'), ({'ransac_px': 0.0}, 'ransac_px')])
def test_bad_settings_are_refused_by_name(settings: dict, key: str) -> None:
    with pytest.raises(ConfigError, match=key):
        TrackerConfig(**settings)


def test_a_hand_covering_most_of_the_image_is_never_tracked() -> None:
    """A hand box over nearly the whole frame: the network's motion, then tracking again."""
    source = texture(9)
    tracker = CameraTracker(TrackerConfig())
    covering = np.array([[5.0, 5.0, WIDTH - 5.0, HEIGHT - 5.0]])
    states = []
    for index in range(20):
        gray, depth = render(source, true_pose(index))
        boxes = covering if 5 <= index < 10 else None
        result = tracker.track(view(gray, depth, boxes), true_pose(index))
        states.append(result.state)
    assert states[5:10] == ['predicted'] * 5
    assert states[11:] == ['tracked'] * 9
    assert errors(result.T_raw, true_pose(19))[1] < 0.5


def test_references_renewed_on_depth_of_varying_scale_keep_the_path() -> None:
    """Points carried into a renewed reference agree with its depth, whatever that depth's scale.

    Each frame's depth is off by its own factor, as the network's is; carried points that were
    not rescaled to the new reference's depth would bend the path by several degrees. References
    are renewed early (``refresh_fraction`` 0.8) so that several renewals happen on any CPU.
    """
    source = texture(0)
    tracker = CameraTracker(TrackerConfig(refresh_fraction=0.8))
    rng = np.random.default_rng(0)
    renewals = 0
    for index in range(120):
        gray, depth = render(source, pan(index))
        before = tracker._reference
        result = tracker.track(view(gray, depth * rng.uniform(0.8, 1.25)), pan(index))
        renewals += before is not None and tracker._reference is not before
        translation_error, rotation_error = errors(result.T_raw, pan(index))
        assert result.state == 'tracked'
        assert rotation_error < 0.5 and translation_error < 0.05, index
    assert renewals >= 3


@pytest.mark.parametrize('after', [False, True])
def test_frames_without_network_pose_or_depth_are_tracked_and_renew_on_depth(
        after: bool) -> None:
    """Depth and the network's pose on every third frame only (and where the tracker asks).

    The frames between are tracked from the points held; a renewal due there waits for the
    next frame with depth, which the tracker asks for. ``after``: a frame due by the interval
    is tracked without them too, and they come afterwards (``absorb``), as the engine does
    without BA. The path stays as exact as with depth on every frame.
    """
    source = texture(0)
    tracker = CameraTracker(TrackerConfig())
    asked = renewals = 0
    last_geometry = 0
    for index in range(120):
        gray, depth = render(source, pan(index))
        geometry = index == 0 or index - last_geometry >= 3 or tracker.needs_depth
        asked += tracker.needs_depth
        before = tracker._reference
        if geometry and after and index and not tracker.needs_depth:
            last_geometry = index
            result = tracker.track(view(gray, None), None)
            assert tracker.absorb(view(gray, depth), pan(index)) is None
            assert not tracker.needs_depth
        elif geometry:
            last_geometry = index
            result = tracker.track(view(gray, depth), pan(index))
            assert not tracker.needs_depth
        else:
            result = tracker.track(view(gray, None), None)
            assert tracker._reference is before  # no renewal without depth
        renewals += before is not None and tracker._reference is not before
        translation_error, rotation_error = errors(result.T_raw, pan(index))
        assert result.state == 'tracked'
        assert rotation_error < 0.5 and translation_error < 0.05, index
    assert renewals >= 1 and asked >= 1, (renewals, asked)


def test_depth_taken_in_one_frame_late_renews_at_its_frame() -> None:
    """As the engine without BA: a frame due for depth is tracked without it, so is the next one.

    Only then do its network pose and depth come (``absorb`` with the tracker's ``moment``
    right after it). A renewal due there happens at that frame, its points are followed into
    the next one and anchored on that frame's pose; the path stays as exact as with depth on
    every frame.
    """
    source = texture(0)
    tracker = CameraTracker(TrackerConfig())
    owed = None  # (index, gray, depth, moment)
    last_view = None  # the last frame tracked
    renewals = 0
    last_geometry = 0
    for index in range(120):
        gray, depth = render(source, pan(index))
        if owed is not None and index - owed[0] == 2:
            before = tracker._reference
            assert tracker.absorb(view(owed[1], owed[2]), pan(owed[0]), owed[3]) is None
            if tracker._reference is not before:
                renewals += 1
                translation_error, rotation_error = errors(tracker._reference.T_raw,
                                                           pan(owed[0]))
                assert rotation_error < 0.5 and translation_error < 0.05
                assert tracker._last_view is last_view and not tracker.needs_depth
            owed = None
        if index == 0:
            result = tracker.track(view(gray, depth), pan(index))
        else:
            last_view = view(gray, None)
            due = owed is None and (index - last_geometry >= 3 or tracker.needs_depth)
            result = tracker.track(last_view, None)
            if due:
                last_geometry = index
                owed = (index, gray, depth, tracker.moment())
        translation_error, rotation_error = errors(result.T_raw, pan(index))
        assert result.state == 'tracked'
        assert rotation_error < 0.5 and translation_error < 0.05, index
    assert renewals >= 1


def test_a_frame_without_depth_that_loses_the_points_holds_the_pose_and_asks_for_depth() -> None:
    source = texture(3)
    tracker = CameraTracker(TrackerConfig())
    for index in range(3):
        gray, depth = render(source, true_pose(index))
        held = tracker.track(view(gray, depth), true_pose(index)).T_raw
    covered = view(np.full_like(gray, 90), None)
    result = tracker.track(covered, None)
    assert result.state == 'predicted' and tracker.needs_depth
    np.testing.assert_array_equal(result.T_raw, held)
    gray, depth = render(source, true_pose(4))
    result = tracker.track(view(gray, depth), true_pose(4))
    assert result.state == 'tracked' and not tracker.needs_depth
    assert errors(result.T_raw, true_pose(4))[1] < 0.5


def test_the_first_frame_needs_the_network_pose() -> None:
    gray, _ = render(texture(0), np.eye(4))
    with pytest.raises(ValueError, match='network pose'):
        CameraTracker(TrackerConfig()).track(view(gray, None), None)


def test_a_lost_frame_whose_geometry_comes_after_is_bridged_by_the_network() -> None:
    """Its answer holds the last pose; ``absorb`` bridges it by the network's motion."""
    source = texture(3)
    tracker = CameraTracker(TrackerConfig())
    for index in range(3):
        gray, depth = render(source, true_pose(index))
        tracker.track(view(gray, depth), true_pose(index))
    covered = np.full_like(gray, 90)
    result = tracker.track(view(covered, None), None)
    assert result.state == 'predicted'
    bridged = tracker.absorb(view(covered, depth), true_pose(3))
    assert errors(bridged, true_pose(3))[1] < 0.5 and tracker.needs_depth
    gray, depth = render(source, true_pose(4))
    result = tracker.track(view(gray, depth), true_pose(4))
    assert result.state == 'tracked' and errors(result.T_raw, true_pose(4))[1] < 0.5
    with pytest.raises(ValueError, match='depth'):
        tracker.absorb(view(gray, None), true_pose(4))
