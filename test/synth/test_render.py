"""Renderer: analytic depths, z-buffer occlusion between the scene and the hands, determinism."""

from infinihand_ros.core import geometry
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import JOINT_PARENTS
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.mano import capsules as caps
from infinihand_ros.synth import render
from infinihand_ros.synth import sensor
from infinihand_ros.synth.camera_motion import sample_intrinsics
from infinihand_ros.synth.render import ArmGeometry
from infinihand_ros.synth.render import Exposure
from infinihand_ros.synth.render import HandGeometry
from infinihand_ros.synth.render import render_frame
from infinihand_ros.synth.render import RenderOptions
from infinihand_ros.synth.scene import Lighting
from infinihand_ros.synth.scene import make_scene
from infinihand_ros.synth.scene import OrientedBox
from infinihand_ros.synth.scene import Scene
from infinihand_ros.synth.scene import TexturedQuad
import numpy as np
import pytest

WIDTH, HEIGHT = 160, 120
K = np.array([[120.0, 0.0, WIDTH / 2], [0.0, 120.0, HEIGHT / 2], [0.0, 0.0, 1.0]])
CLEAN = RenderOptions(noise_sigma=0.0)
SKIN = (200, 150, 120)


def _lighting() -> Lighting:
    return Lighting(ambient=0.6, diffuse=0.4, direction_world=np.array([0.0, -0.6, -0.8]),
                    lamp_world=np.array([0.0, -1.0, 0.0]), lamp=0.0, tint=np.ones(3))


def _quad(origin: list, edge_u: list, edge_v: list, seed: int = 0) -> TexturedQuad:
    rng = np.random.default_rng(seed)
    texture = rng.integers(0, 256, (32, 32, 3), dtype=np.uint8)
    return TexturedQuad(np.array(origin, float), np.array(edge_u, float), np.array(edge_v, float),
                        texture, 'test')


def _scene(*quads: TexturedQuad) -> Scene:
    """Build a scene of the given quads, camera frame = world frame in the tests below."""
    box = OrientedBox(np.zeros(3), np.ones(3))
    return Scene(tuple(quads), box, box, (), _lighting())


def _wall(depth_m: float, half_m: float = 3.0) -> TexturedQuad:
    """Build a fronto-parallel quad facing a camera at the origin looking along +z."""
    return _quad([-half_m, -half_m, depth_m], [2 * half_m, 0, 0], [0, 2 * half_m, 0])


def _blob_hand(side: int, centre: list, radius: float = 0.02) -> HandGeometry:
    """Build a 'hand' whose joints all sit on one point: every capsule is the same sphere."""
    joints = np.tile(np.array(centre, float), (NUM_JOINTS, 1))
    return HandGeometry(side, joints, np.full(NUM_JOINTS, radius), SKIN)


def _flat_hand(side: int, wrist: list, scale: float = 1.0) -> HandGeometry:
    """Build a flat open hand in a plane z = const, fingers along -y (up in the image)."""
    joints = np.zeros((NUM_JOINTS, 3))
    joints[0] = wrist
    spread = (-0.03, -0.01, 0.01, 0.03) if side == RIGHT else (0.03, 0.01, -0.01, -0.03)
    for finger, offset in enumerate(spread):
        for level in range(4):
            joints[5 + 4 * finger + level] = np.add(wrist, [offset, -0.08 - 0.025 * level, 0])
    thumb_dir = -1.0 if side == RIGHT else 1.0
    for level in range(4):
        joints[1 + level] = np.add(wrist, [thumb_dir * (0.03 + 0.02 * level), -0.02 - 0.02 * level,
                                           0])
    joints = np.asarray(wrist) + (joints - np.asarray(wrist)) * scale
    return HandGeometry(side, joints, np.full(NUM_JOINTS, 0.01), SKIN)


def _pixel_ray(u: float, v: float) -> np.ndarray:
    return np.linalg.solve(K, np.array([u, v, 1.0]))


def test_plane_depth_equals_the_analytic_ray_plane_depth() -> None:
    normal = np.array([0.3, -0.2, -1.0])
    normal /= np.linalg.norm(normal)
    # A big oblique quad through (0, 0, 2) with that normal (edge_v x edge_u = normal).
    edge_u = np.cross(normal, [0.0, 1.0, 0.0])
    edge_u *= 8.0 / np.linalg.norm(edge_u)
    edge_v = np.cross(edge_u, normal)
    edge_v *= 8.0 / np.linalg.norm(edge_v)
    origin = np.array([0.0, 0.0, 2.0]) - 0.5 * (edge_u + edge_v)
    quad = TexturedQuad(origin, edge_u, edge_v, np.full((16, 16, 3), 128, np.uint8))
    np.testing.assert_allclose(quad.normal, normal, atol=1e-12)
    out = render_frame(_scene(quad), K, np.eye(4), WIDTH, HEIGHT, [], CLEAN)
    for u, v in [(0, 0), (80, 60), (159, 119), (20, 100), (140, 7)]:
        ray = _pixel_ray(u, v)
        expected = (normal @ np.array([0.0, 0.0, 2.0])) / (normal @ ray)
        assert out.depth[v, u] == pytest.approx(expected, rel=1e-5)


def test_back_face_is_not_drawn_and_empty_pixels_have_infinite_depth() -> None:
    back = _quad([-3, 3, 2.0], [6, 0, 0], [0, -6, 0])  # same plane as a wall, facing away
    out = render_frame(_scene(back), K, np.eye(4), WIDTH, HEIGHT, [], CLEAN)
    assert np.all(np.isinf(out.depth))
    assert not out.rgb.any()


def test_quad_crossing_the_near_plane_is_clipped() -> None:
    floor = _quad([-2, 0.5, -1.0], [4, 0, 0], [0, 0, 4])  # y = 0.5 plane, from z=-1 to z=3
    floor = TexturedQuad(floor.origin + floor.edge_v, floor.edge_u, -floor.edge_v, floor.texture)
    out = render_frame(_scene(floor), K, np.eye(4), WIDTH, HEIGHT, [], CLEAN)
    finite = np.isfinite(out.depth)
    assert finite[-1].all() and not finite[0].any()  # floor below the horizon only
    assert out.depth[finite].min() >= CLEAN.near_m
    u, v = 30, HEIGHT - 1
    assert out.depth[v, u] == pytest.approx(0.5 / _pixel_ray(u, v)[1], rel=1e-5)


def test_sphere_in_front_renders_at_distance_minus_radius() -> None:
    distance, radius = 0.6, 0.05
    hand = _blob_hand(RIGHT, [0.0, 0.0, distance], radius)
    out = render_frame(_scene(_wall(3.0)), K, np.eye(4), WIDTH, HEIGHT, [hand], CLEAN)
    cy, cx = HEIGHT // 2, WIDTH // 2
    assert out.depth[cy, cx] == pytest.approx(distance - radius, abs=1e-5)
    assert out.hand_masks[RIGHT, cy, cx] and not out.hand_masks[LEFT].any()
    # Silhouette radius of a sphere: f * r / sqrt(d^2 - r^2).
    expected_px = K[0, 0] * radius / np.sqrt(distance ** 2 - radius ** 2)
    assert out.hand_masks[RIGHT, cy].sum() == pytest.approx(2 * expected_px, abs=2.0)


def test_capsule_across_the_view_has_analytic_depth() -> None:
    distance, radius = 0.5, 0.02
    assert len(caps.build_capsule_set([]).radii) == 0
    capsules = caps.CapsuleSet(np.array([[-0.1, 0.0, distance]]), np.array([[0.1, 0.0, distance]]),
                               np.array([[radius, radius]]), np.array([True]), np.array([True]),
                               np.array([RIGHT]))
    rx = ((np.arange(WIDTH) - K[0, 2]) / K[0, 0])[None, :]
    ry = ((np.arange(HEIGHT) - K[1, 2]) / K[1, 1])[:, None]
    depth = caps.ray_capsule_depth(rx, ry, capsules, 0)
    centre = depth[HEIGHT // 2]
    # Rays of the centre row lie in the plane y = 0 and meet the cylinder y^2 + (z - d)^2 = r^2
    # at z = d - r wherever x is within the segment.
    assert centre[WIDTH // 2] == pytest.approx(distance - radius, abs=1e-9)
    assert centre[WIDTH // 2 + 20] == pytest.approx(distance - radius, abs=1e-9)
    assert np.isnan(depth[0, 0])  # a ray far above the capsule misses


def _round_cone_distance(points: np.ndarray, start: np.ndarray, end: np.ndarray,
                         radii: tuple[float, float]) -> np.ndarray:
    """Signed distance (N,) of points (N, 3) to a round cone, by brute force.

    The round cone is the union of the spheres along its segment, radius interpolated linearly
    (the convex hull of the end spheres); sampled densely along the segment.
    """
    along = np.linspace(0.0, 1.0, 4001)
    centres = start + along[:, None] * (end - start)
    sphere_radii = radii[0] + along * (radii[1] - radii[0])
    gaps = np.linalg.norm(points[:, None] - centres[None], axis=2) - sphere_radii[None]
    return gaps.min(axis=1)


@pytest.mark.parametrize('seed', range(6))
def test_round_cone_hits_and_normals_match_its_distance_function(seed: int) -> None:
    rng = np.random.default_rng(seed)
    start = np.array([rng.uniform(-0.04, 0.04), rng.uniform(-0.04, 0.04), rng.uniform(0.3, 0.5)])
    end = start + rng.normal(scale=0.04, size=3)
    radii = tuple(rng.uniform(0.005, 0.03, size=2))
    capsules = caps.CapsuleSet(start[None], end[None], np.array([radii]), np.array([True]),
                               np.array([True]), np.array([RIGHT]))
    rx = np.linspace(-0.2, 0.2, 40)[None, :]
    ry = np.linspace(-0.15, 0.15, 30)[:, None]
    depth = caps.ray_capsule_depth(rx, ry, capsules, 0)
    rays = np.stack(np.broadcast_arrays(rx, ry, np.ones_like(depth)), axis=-1)
    hit = np.isfinite(depth)
    assert 20 < hit.sum() < hit.size
    points = rays[hit] * depth[hit][:, None]
    np.testing.assert_allclose(_round_cone_distance(points, start, end, radii), 0.0, atol=1e-6)
    # The first hit: nothing of the cone lies on the ray before it, and missed rays miss it.
    before = rays[hit] * (depth[hit] - 1e-4)[:, None]
    assert np.all(_round_cone_distance(before, start, end, radii) > 0.0)
    for t in np.linspace(0.25, 0.6, 36):
        assert np.all(_round_cone_distance(rays[~hit] * t, start, end, radii) > -1e-4)
    # Normals: the distance function's gradient.
    normals = caps.surface_normals(points, capsules, np.zeros(len(points), int))
    step = 1e-6
    gradient = np.stack([_round_cone_distance(points + step * axis, start, end, radii)
                         - _round_cone_distance(points - step * axis, start, end, radii)
                         for axis in np.eye(3)], axis=1)
    gradient /= np.linalg.norm(gradient, axis=1, keepdims=True)
    assert np.einsum('ij,ij->i', normals, gradient).min() > np.cos(np.radians(0.5))


def test_hand_behind_the_table_is_masked_out_and_in_front_is_not() -> None:
    table = _quad([-0.5, -0.5, 1.0], [1.0, 0, 0], [0, 1.0, 0])
    scene = _scene(table, _wall(3.0))
    behind = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT,
                          [_flat_hand(RIGHT, [0.0, 0.1, 1.3])], CLEAN)
    assert not behind.hand_masks.any()
    front = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT,
                         [_flat_hand(RIGHT, [0.0, 0.1, 0.7])], CLEAN)
    mask = front.hand_masks[RIGHT]
    assert mask.sum() > 200
    assert np.all(front.depth[mask] < 1.0)


def test_hand_partly_behind_a_table_edge_is_cut_at_the_edge() -> None:
    edge = _quad([-0.5, 0.0, 0.8], [1.0, 0, 0], [0, 1.0, 0])  # covers the lower image half
    scene = _scene(edge, _wall(3.0))
    out = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT, [_flat_hand(LEFT, [0.0, 0.05, 1.0])],
                       CLEAN)
    rows = np.flatnonzero(out.hand_masks[LEFT].any(axis=1))
    assert rows.size > 0 and rows.max() <= HEIGHT // 2  # nothing below the edge at v = cy


def test_overlapping_hands_give_disjoint_masks_and_the_nearer_wins() -> None:
    scene = _scene(_wall(3.0))
    near = _flat_hand(LEFT, [0.0, 0.08, 0.5])
    far = _flat_hand(RIGHT, [0.03, 0.08, 0.6])
    solo_near = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT, [near], CLEAN).hand_masks[LEFT]
    solo_far = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT, [far], CLEAN).hand_masks[RIGHT]
    assert (solo_near & solo_far).sum() > 100  # they do overlap in the image
    both = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT, [far, near], CLEAN)
    assert not (both.hand_masks[LEFT] & both.hand_masks[RIGHT]).any()
    np.testing.assert_array_equal(both.hand_masks[LEFT], solo_near)
    np.testing.assert_array_equal(both.hand_masks[RIGHT], solo_far & ~solo_near)


def test_hands_outside_or_behind_the_camera_are_fine() -> None:
    scene = _scene(_wall(3.0))
    hands = [_flat_hand(LEFT, [0.35, 0.0, 0.5]), _blob_hand(RIGHT, [0.0, 0.0, -0.5])]
    out = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT, hands, CLEAN)
    assert 0 < out.hand_masks[LEFT].sum() < 0.5 * _solo_area(_flat_hand(LEFT, [0.0, 0.0, 0.5]))
    assert not out.hand_masks[RIGHT].any()


def _solo_area(hand: HandGeometry) -> int:
    out = render_frame(_scene(_wall(3.0)), K, np.eye(4), WIDTH, HEIGHT, [hand], CLEAN)
    return int(out.hand_masks[hand.side].sum())


@pytest.fixture(scope='module')
def room() -> Scene:
    return make_scene(np.random.default_rng(11))


def _room_view(room: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Place a camera above the table edge looking at the table centre; hands go there."""
    target = room.table_top_center
    eye = target + np.array([0.0, -0.7, 0.8])
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([right, np.cross(forward, right), forward], axis=1)
    pose[:3, 3] = eye
    return pose, target


def _room_hands(pose: np.ndarray, target: np.ndarray) -> list[HandGeometry]:
    hands = []
    for side, dx in ((LEFT, -0.08), (RIGHT, 0.08)):
        local = _flat_hand(side, [0.0, 0.0, 0.0]).joints_world
        world = local @ pose[:3, :3].T + target + np.array([dx, -0.2, 0.12])
        hands.append(HandGeometry(side, world, np.full(NUM_JOINTS, 0.01), SKIN))
    return hands


def test_room_render_masks_are_on_finite_depth_and_in_front_of_the_scene(room: Scene) -> None:
    pose, target = _room_view(room)
    k = sample_intrinsics(np.random.default_rng(0), WIDTH, HEIGHT)
    empty = render_frame(room, k, pose, WIDTH, HEIGHT, [], CLEAN)
    out = render_frame(room, k, pose, WIDTH, HEIGHT, _room_hands(pose, target), CLEAN)
    assert np.isfinite(empty.depth).all()  # closed room: every pixel sees a surface
    assert out.rgb.dtype == np.uint8 and out.rgb.shape == (HEIGHT, WIDTH, 3)
    assert out.depth.dtype == np.float32 and out.hand_masks.shape == (2, HEIGHT, WIDTH)
    for side in (LEFT, RIGHT):
        mask = out.hand_masks[side]
        assert mask.sum() > 50
        assert np.isfinite(out.depth[mask]).all()
        assert np.all(out.depth[mask] < empty.depth[mask])
    unchanged = ~out.hand_masks.any(axis=0)
    np.testing.assert_array_equal(out.depth[unchanged], empty.depth[unchanged])


def test_render_is_deterministic_and_the_noise_follows_its_seed(room: Scene) -> None:
    pose, target = _room_view(room)
    hands = _room_hands(pose, target)
    first = render_frame(room, K, pose, WIDTH, HEIGHT, hands, RenderOptions(noise_seed=3))
    again = render_frame(room, K, pose, WIDTH, HEIGHT, hands, RenderOptions(noise_seed=3))
    other = render_frame(room, K, pose, WIDTH, HEIGHT, hands, RenderOptions(noise_seed=4))
    np.testing.assert_array_equal(first.rgb, again.rgb)
    np.testing.assert_array_equal(first.depth, again.depth)
    assert np.any(first.rgb != other.rgb)
    np.testing.assert_array_equal(first.hand_masks, other.hand_masks)
    other_scene = make_scene(np.random.default_rng(12))
    assert np.any(render_frame(other_scene, K, pose, WIDTH, HEIGHT, hands, CLEAN).rgb
                  != render_frame(room, K, pose, WIDTH, HEIGHT, hands, CLEAN).rgb)


def test_noise_has_the_requested_sigma(room: Scene) -> None:
    pose, _ = _room_view(room)
    clean = render_frame(room, K, pose, WIDTH, HEIGHT, [], CLEAN).rgb.astype(float)
    noisy = render_frame(room, K, pose, WIDTH, HEIGHT, [], RenderOptions(noise_sigma=4.0)).rgb
    diff = noisy.astype(float) - clean
    inside = (clean > 20) & (clean < 235)  # away from clipping
    assert diff[inside].std() == pytest.approx(4.0, rel=0.15)
    assert abs(diff[inside].mean()) < 0.2


def _yaw(pose: np.ndarray, angle_rad: float) -> np.ndarray:
    """Turn a pose about its own camera y axis (the image's vertical) by ``angle_rad``."""
    turn = np.eye(4)
    turn[:3, :3] = geometry.axis_angle_to_matrix(np.array([0.0, angle_rad, 0.0]))
    return pose @ turn


def _still(pose: np.ndarray, hands: list[HandGeometry]) -> Exposure:
    joints = np.array([hand.joints_world for hand in hands]).reshape(len(hands), NUM_JOINTS, 3)
    return Exposure(np.stack([pose, pose]), np.stack([joints, joints]))


def test_a_turning_camera_blurs_an_edge_by_its_motion_only_while_exposed() -> None:
    texture = np.zeros((64, 64, 3), np.uint8)
    texture[:, 32:] = 255
    wall = TexturedQuad(np.array([-3.0, -3.0, 2.0]), np.array([6.0, 0.0, 0.0]),
                        np.array([0.0, 6.0, 0.0]), texture, 'edge')
    scene, pose = _scene(wall), np.eye(4)
    still = render_frame(scene, K, pose, WIDTH, HEIGHT, [], CLEAN)
    np.testing.assert_array_equal(
        render_frame(scene, K, pose, WIDTH, HEIGHT, [], CLEAN, _still(pose, [])).rgb, still.rgb)
    angle = 0.1  # the edge sweeps f * angle = 12 px while the shutter is open
    turning = Exposure(np.stack([_yaw(pose, -angle / 2), _yaw(pose, angle / 2)]),
                       np.zeros((2, 0, NUM_JOINTS, 3)))
    blurred = render_frame(scene, K, pose, WIDTH, HEIGHT, [], CLEAN, turning)
    np.testing.assert_array_equal(blurred.depth, still.depth)

    def spread(rgb: np.ndarray) -> float:
        """Variance (px^2) of where the centre row steps up (its derivative as a density)."""
        step = np.diff(rgb[HEIGHT // 2, :, 1].astype(float))
        where = np.arange(len(step))
        mean = np.average(where, weights=step)
        return float(np.average((where - mean) ** 2, weights=step))

    # A sweep of length L adds L^2 / 12 to the variance (a box), (n + 1) / (n - 1) times that
    # for the n samples of the exposure; 12 px need all EXPOSURE_SAMPLES.
    samples = sensor.EXPOSURE_SAMPLES
    sweep = np.sqrt(12.0 * (spread(blurred.rgb) - spread(still.rgb))
                    * (samples - 1) / (samples + 1))
    assert sweep == pytest.approx(K[0, 0] * angle, rel=0.1)
    # Along the edge (vertically) nothing moves.
    np.testing.assert_array_equal(blurred.rgb[HEIGHT // 2 - 20], blurred.rgb[HEIGHT // 2 + 20])


def test_a_moving_hand_is_smeared_along_its_path_and_its_truth_stays_sharp() -> None:
    scene = _scene(_wall(3.0))
    hand = _blob_hand(RIGHT, [0.0, 0.0, 0.6], 0.05)
    travel = np.array([0.06, 0.0, 0.0])  # 12 px at 0.6 m while the shutter is open
    joints = np.stack([hand.joints_world - travel / 2, hand.joints_world + travel / 2])[:, None]
    exposure = Exposure(np.stack([np.eye(4), np.eye(4)]), joints)
    still = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT, [hand], CLEAN)
    moving = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT, [hand], CLEAN, exposure)
    np.testing.assert_array_equal(moving.depth, still.depth)
    np.testing.assert_array_equal(moving.hand_masks, still.hand_masks)
    changed = np.abs(moving.rgb.astype(int) - still.rgb.astype(int)).max(axis=-1) > 8
    cols = np.flatnonzero(still.hand_masks[RIGHT].any(axis=0))
    sweep = K[0, 0] * travel[0] / 0.6
    # The hand spreads sideways over the wall, about half its sweep on each side; rows above
    # and below it, and the wall beyond its reach, do not change.
    spread = np.flatnonzero(changed[HEIGHT // 2])
    assert spread.min() < cols.min() - sweep / 4 and spread.max() > cols.max() + sweep / 4
    assert spread.min() > cols.min() - sweep and spread.max() < cols.max() + sweep
    rows = np.flatnonzero(still.hand_masks[RIGHT].any(axis=1))
    assert not changed[:rows.min() - 2].any() and not changed[rows.max() + 3:].any()


def test_a_hand_casts_a_soft_shadow_where_it_keeps_the_lamp_from_the_wall() -> None:
    lamp = Lighting(ambient=0.6, diffuse=0.0, direction_world=np.array([0.0, 0.0, -1.0]),
                    lamp_world=np.array([1.0, 0.0, 0.0]), lamp=1.0, tint=np.ones(3))
    scene = Scene((_wall(1.0),), OrientedBox(np.zeros(3), np.ones(3)),
                  OrientedBox(np.zeros(3), np.ones(3)), (), lamp)
    hand = _blob_hand(RIGHT, [0.0, 0.0, 0.8], 0.05)
    bare = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT, [], CLEAN)
    lit = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT, [hand], CLEAN)
    np.testing.assert_array_equal(lit.depth[~lit.hand_masks[RIGHT]],
                                  bare.depth[~lit.hand_masks[RIGHT]])
    ratio = (lit.rgb.astype(float) + 1.0) / (bare.rgb.astype(float) + 1.0)
    # From the lamp at x = 1 m through the sphere at 0.8 m to the wall at 1 m: centred at
    # x = -0.25 m (pixel 50 of the centre row), 0.0625 m (7.5 px) high and, the light coming in
    # at 1 / cos = 1.6, 12 px wide; there the wall keeps only its ambient light: 0.6 of
    # 0.6 + 0.176 (the lamp's Lambert term).
    centre = ratio[HEIGHT // 2, 50]
    np.testing.assert_allclose(centre, 0.6 / (0.6 + 0.625 / (1.0 + 1.6 ** 2)), atol=0.04)
    # Softly: partly lit at its rim; the wall away from it keeps all its light.
    assert centre[1] + 0.05 < ratio[HEIGHT // 2 + 8, 50, 1] < 0.99
    np.testing.assert_allclose(ratio[HEIGHT // 2, :30], 1.0, atol=0.02)
    np.testing.assert_allclose(ratio[HEIGHT // 2, 120:], 1.0, atol=0.01)
    np.testing.assert_allclose(ratio[:HEIGHT // 2 - 15], 1.0, atol=0.02)


def test_bad_inputs_raise_clear_errors(room: Scene) -> None:
    hand = _blob_hand(LEFT, [0, 0, 1])
    with pytest.raises(InputError, match='K: expected shape'):
        render_frame(room, np.eye(2), np.eye(4), WIDTH, HEIGHT, [], CLEAN)
    with pytest.raises(InputError, match='at most one hand per side'):
        render_frame(room, K, np.eye(4), WIDTH, HEIGHT, [hand, hand], CLEAN)
    with pytest.raises(InputError, match='image size must be positive'):
        render_frame(room, K, np.eye(4), 0, HEIGHT, [], CLEAN)
    with pytest.raises(InputError, match='joints_world: expected shape'):
        HandGeometry(LEFT, np.zeros((20, 3)), np.ones(NUM_JOINTS), SKIN)
    with pytest.raises(InputError, match='radii must be positive'):
        HandGeometry(LEFT, np.zeros((NUM_JOINTS, 3)), np.zeros(NUM_JOINTS), SKIN)
    with pytest.raises(InputError, match='side must be 0'):
        HandGeometry(2, np.zeros((NUM_JOINTS, 3)), np.ones(NUM_JOINTS), SKIN)
    with pytest.raises(InputError, match='noise_sigma must be >= 0'):
        RenderOptions(noise_sigma=-1.0)


def test_hand_capsules_cover_bones_knuckles_thenar_and_palm_rim() -> None:
    hand = _flat_hand(RIGHT, [0.0, 0.0, 0.5])
    joint_radii = caps.joint_radii(np.zeros(10))
    starts, ends, radii = caps.hand_capsules(hand.joints_world, joint_radii, RIGHT)
    assert len(starts) == 15 + 4 + 1 + 7  # finger bones, knuckles, thenar, palm rim
    children = list(caps.BONE_CHILDREN)
    np.testing.assert_array_equal(ends[:15], hand.joints_world[children])
    # Bones taper from joint to joint: each ends on its joint's sphere, where the next begins.
    np.testing.assert_array_equal(radii[:15, 1], joint_radii[children])
    parents = [JOINT_PARENTS[child] for child in children]
    np.testing.assert_array_equal(radii[:15, 0], joint_radii[parents])
    assert np.all(radii[:15, 0] > radii[:15, 1])
    capsule_set = caps.build_capsule_set([(hand.joints_world, hand.radii, RIGHT)])
    # Each distinct sphere is intersected once: fewer caps than 2 per capsule.
    assert capsule_set.start_caps.sum() + capsule_set.end_caps.sum() < 2 * len(starts)
    np.testing.assert_array_equal(capsule_set.sides, RIGHT)


def test_palm_face_is_flat_at_the_slab_half_thickness() -> None:
    hand = _flat_hand(RIGHT, [0.0, 0.0, 0.5])  # palm faces away (+z), see the next test
    palms = caps.build_palm_set([(hand.joints_world, hand.radii, RIGHT)])
    scale = hand.radii[0] / caps.JOINT_RADII_M[0]
    near_face = 0.5 + (caps.PALM_OFFSET_M - caps.PALM_HALF_THICKNESS_M) * scale
    rx = ((np.arange(WIDTH) - K[0, 2]) / K[0, 0])[None, :]
    ry = ((np.arange(HEIGHT) - K[1, 2]) / K[1, 1])[:, None]
    depth = caps.ray_palm_depth(rx, ry, palms, 0)
    centre = hand.joints_world[[0, 9]].mean(axis=0)
    u, v = (centre[:2] / centre[2] * K[0, 0] + K[:2, 2]).round().astype(int)
    assert depth[v, u] == pytest.approx(near_face, abs=1e-9)
    assert np.isnan(depth[0, 0])
    normals = caps.palm_normals(np.array([[0.0, 0.0, 1.0]]), palms, np.zeros(1, int))
    np.testing.assert_allclose(normals, [[0.0, 0.0, -1.0]])  # towards the camera


def _arm(hand: HandGeometry) -> ArmGeometry:
    """Build an arm from the hand's wrist down the image (+y) and back towards the camera."""
    wrist = hand.joints_world[0]
    points = wrist + np.array([[0.0, 0.0, 0.0], [0.0, 0.08, 0.0], [0.0, 0.25, -0.05],
                               [0.0, 0.4, -0.3]])
    return ArmGeometry(points, np.array([0.027, 0.036, 0.045]), (90, 90, 140))


def test_an_arm_occludes_like_a_hand_but_is_not_in_its_mask() -> None:
    scene = _scene(_wall(3.0))
    hand = _flat_hand(RIGHT, [0.0, -0.02, 0.5])
    bare = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT, [hand], CLEAN)
    armed = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT,
                         [HandGeometry(hand.side, hand.joints_world, hand.radii, SKIN,
                                       _arm(hand))], CLEAN)
    mask, bare_mask = armed.hand_masks[RIGHT], bare.hand_masks[RIGHT]
    assert not (mask & ~bare_mask).any()  # the arm never enters the hand's mask
    covered = bare_mask & ~mask  # the forearm, thicker than the wrist, hides a little of it
    assert covered.sum() < 0.1 * bare_mask.sum()
    assert np.all(armed.depth[covered] < bare.depth[covered])
    arm = (armed.depth < 2.9) & ~mask
    assert arm.sum() > 500 and arm[-1].any()  # the arm leaves the image at the bottom
    np.testing.assert_array_equal(armed.depth[mask], bare.depth[mask])


def test_palm_and_nail_normals_follow_the_hand() -> None:
    back_view = _flat_hand(RIGHT, [0.0, 0.0, 0.5]).joints_world  # palm faces away (+z)
    palm = render._palm_normal(back_view, RIGHT)
    np.testing.assert_allclose(palm, [0.0, 0.0, 1.0], atol=1e-9)
    nails = render._nail_normals(back_view, palm)
    np.testing.assert_allclose(nails[1:], np.tile([0.0, 0.0, -1.0], (4, 1)), atol=1e-9)
    assert not nails[0].any()  # no nail normal for the thumb
    curled = back_view.copy()
    curled[8] = curled[7] + [0.0, 0.0, 0.025]  # index tip bent 90 degrees towards the palm
    np.testing.assert_allclose(render._nail_normals(curled, palm)[1], [0.0, -1.0, 0.0],
                               atol=1e-9)
    mirrored = _flat_hand(LEFT, [0.0, 0.0, 0.5]).joints_world
    np.testing.assert_allclose(render._palm_normal(mirrored, LEFT), [0.0, 0.0, 1.0], atol=1e-9)


def test_nails_are_lighter_on_the_back_of_the_fingertips_only() -> None:
    scene = _scene(_wall(3.0))
    back = _flat_hand(RIGHT, [0.0, 0.02, 0.4])
    out = render_frame(scene, K, np.eye(4), WIDTH, HEIGHT, [back], CLEAN)
    frame = render._new_frame(K, np.eye(4), WIDTH, HEIGHT, CLEAN.near_m)
    bodies = render._bodies(frame, [back])
    tips = back.joints_world[[8, 12, 16, 20]]
    mids = 0.5 * (back.joints_world[[5, 9, 13, 17]] + back.joints_world[[6, 10, 14, 18]])
    tip_px = (tips[:, :2] / tips[:, 2:] * K[0, 0] + K[:2, 2]).round().astype(int)
    mid_px = (mids[:, :2] / mids[:, 2:] * K[0, 0] + K[:2, 2]).round().astype(int)
    brightness = out.rgb.astype(float).sum(axis=2)
    lighter = brightness[tip_px[:, 1], tip_px[:, 0]] - brightness[mid_px[:, 1], mid_px[:, 0]]
    assert np.all(lighter > 20)
    assert np.count_nonzero(bodies.nail_normals.any(axis=1)) == 4


def test_wrap_lighting_reaches_past_the_terminator() -> None:
    light = _lighting()
    normals = np.array([light.direction_world, -light.direction_world])
    points = np.zeros((2, 3))
    lambert = light.shade(points, normals)
    wrapped = light.shade(points, normals, wrap=0.5)
    np.testing.assert_allclose(lambert, [light.ambient + light.diffuse, light.ambient])
    assert wrapped[0] == pytest.approx(lambert[0])
    sideways = np.cross(light.direction_world, [1.0, 0.0, 0.0])
    sideways /= np.linalg.norm(sideways)
    assert light.shade(points[:1], sideways[None], wrap=0.5)[0] > light.ambient


def test_jpeg_compression_is_mild_and_validated(room: Scene) -> None:
    pose, target = _room_view(room)
    hands = _room_hands(pose, target)
    clean = render_frame(room, K, pose, WIDTH, HEIGHT, hands, CLEAN)
    jpeg = render_frame(room, K, pose, WIDTH, HEIGHT, hands, RenderOptions(noise_sigma=0.0,
                                                                           jpeg_quality=90))
    rmse = np.sqrt(np.mean((jpeg.rgb.astype(float) - clean.rgb.astype(float)) ** 2))
    assert 0.0 < rmse < 8.0
    np.testing.assert_array_equal(jpeg.hand_masks, clean.hand_masks)
    with pytest.raises(InputError, match='jpeg_quality'):
        RenderOptions(jpeg_quality=101)
    with pytest.raises(InputError, match='ArmGeometry.radii'):
        ArmGeometry(np.zeros((4, 3)), np.zeros(3), (0, 0, 0))
