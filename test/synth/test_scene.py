"""Procedural scenes and textures: determinism, layout, orientation and texture richness."""

import cv2
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import InputError
from infinihand_ros.synth import textures
from infinihand_ros.synth.scene import make_scene
from infinihand_ros.synth.scene import OrientedBox
from infinihand_ros.synth.scene import Scene
from infinihand_ros.synth.scene import SceneConfig
import numpy as np
import pytest


@pytest.fixture(scope='module')
def scene() -> Scene:
    return make_scene(np.random.default_rng(7))


def _quads_named(scene: Scene, prefix: str) -> list:
    return [quad for quad in scene.quads if quad.name.startswith(prefix)]


def test_same_seed_gives_the_same_scene_and_another_seed_differs(scene: Scene) -> None:
    again = make_scene(np.random.default_rng(7))
    other = make_scene(np.random.default_rng(8))
    assert len(again.quads) == len(scene.quads)
    for first, second in zip(scene.quads, again.quads):
        np.testing.assert_array_equal(first.texture, second.texture)
        np.testing.assert_array_equal(first.origin, second.origin)
    assert not np.allclose(other.table.half_extents, scene.table.half_extents)
    assert not np.array_equal(other.quads[0].texture[:8, :8], scene.quads[0].texture[:8, :8])


def test_world_frame_is_z_up_with_the_floor_at_zero(scene: Scene) -> None:
    floor = _quads_named(scene, 'floor')[0]
    np.testing.assert_allclose(floor.normal, [0.0, 0.0, 1.0], atol=1e-12)
    assert np.all(floor.corners()[:, 2] == 0.0)
    config = SceneConfig()
    assert config.table_height_range_m[0] <= scene.table_top_z <= config.table_height_range_m[1]
    np.testing.assert_allclose(scene.table_top_center[2], scene.table_top_z)
    assert scene.table.center[2] - scene.table.half_extents[2] == pytest.approx(0.0)


def test_room_faces_point_inwards_and_solid_faces_outwards(scene: Scene) -> None:
    room_centre = scene.room.center
    for quad in scene.quads:
        centre = quad.corners().mean(axis=0)
        np.testing.assert_allclose(np.linalg.norm(quad.normal), 1.0)
        if quad.name.startswith(('wall', 'floor', 'ceiling')):
            assert quad.normal @ (room_centre - centre) > 0.0, quad.name
    for index, box in enumerate(scene.boxes):
        for quad in _quads_named(scene, f'box{index}_'):
            outward = quad.corners().mean(axis=0) - box.center
            assert quad.normal @ outward > 0.0
    assert len(_quads_named(scene, 'table_')) == 6 and len(_quads_named(scene, 'leg')) == 16


def test_boxes_stand_on_the_table_without_overlapping(scene: Scene) -> None:
    config = SceneConfig()
    assert config.num_boxes_range[0] <= len(scene.boxes) <= config.num_boxes_range[1]
    top = scene.table
    for box in scene.boxes:
        assert box.center[2] - box.half_extents[2] == pytest.approx(scene.table_top_z)
        corners = np.array([[sx, sy, 0.0] for sx in (-1, 1) for sy in (-1, 1)])
        footprint = box.center + (corners * box.half_extents) @ box.axes()
        assert np.all(np.abs(footprint[:, :2] - top.center[:2]) <= top.half_extents[:2])
    for i, first in enumerate(scene.boxes):
        for second in scene.boxes[i + 1:]:
            gap = np.linalg.norm(first.center[:2] - second.center[:2])
            assert gap > np.linalg.norm(first.half_extents[:2])
    assert scene.obstacles == (scene.table, *scene.boxes)


def test_room_leaves_clearance_around_the_table(scene: Scene) -> None:
    config = SceneConfig()
    room_min = scene.room.center[:2] - scene.room.half_extents[:2]
    room_max = scene.room.center[:2] + scene.room.half_extents[:2]
    table_min = scene.table.center[:2] - scene.table.half_extents[:2]
    table_max = scene.table.center[:2] + scene.table.half_extents[:2]
    assert np.all(table_min - room_min >= config.table_clearance_m - 1e-9)
    assert np.all(room_max - table_max >= config.table_clearance_m - 1e-9)


def test_oriented_box_contains_points_in_its_own_axes() -> None:
    box = OrientedBox(np.array([1.0, 0.0, 0.5]), np.array([0.5, 0.1, 0.5]), np.pi / 2)
    points = np.array([[1.0, 0.4, 0.5], [1.4, 0.0, 0.5], [1.0, 0.0, 1.2]])
    np.testing.assert_array_equal(box.contains(points), [True, False, False])
    np.testing.assert_array_equal(box.contains(points, margin_m=0.7), [True, True, True])


def test_textures_are_rich_enough_to_track(scene: Scene) -> None:
    for quad in _quads_named(scene, 'floor') + _quads_named(scene, 'table_4'):
        grey = cv2.cvtColor(quad.texture, cv2.COLOR_RGB2GRAY)
        patch = grey[:200, :200]
        corners = cv2.goodFeaturesToTrack(patch, maxCorners=500, qualityLevel=0.01,
                                          minDistance=5)
        assert corners is not None and len(corners) >= 40, quad.name
        assert patch.std() > 8.0


def test_make_texture_is_deterministic_and_sized() -> None:
    first = textures.make_texture(np.random.default_rng(1), 40, 70)
    second = textures.make_texture(np.random.default_rng(1), 40, 70)
    assert first.shape == (40, 70, 3) and first.dtype == np.uint8
    np.testing.assert_array_equal(first, second)
    with pytest.raises(InputError, match='at least 8 px'):
        textures.make_texture(np.random.default_rng(1), 4, 70)


def test_lighting_is_baked_into_the_textures(scene: Scene) -> None:
    shade_up = scene.lighting.shade(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 1.0]]))
    shade_down = scene.lighting.shade(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, -1.0]]))
    assert shade_up[0] > shade_down[0] >= scene.lighting.ambient
    # Same seed, only the ambient light differs: every surface gets brighter by the same offset
    # of the shading factor, so the bright scene is brighter everywhere.
    dark = make_scene(np.random.default_rng(3), SceneConfig(ambient_range=(0.2, 0.2)))
    bright = make_scene(np.random.default_rng(3), SceneConfig(ambient_range=(0.6, 0.6)))
    for first, second in zip(dark.quads, bright.quads):
        assert first.name == second.name
        assert second.texture.astype(float).mean() > first.texture.astype(float).mean() + 5.0


def test_bad_scene_config_is_rejected() -> None:
    with pytest.raises(ConfigError, match='room_half_extent_range_m'):
        SceneConfig(room_half_extent_range_m=(1.0, 1.2))
    with pytest.raises(ConfigError, match='num_boxes_range'):
        SceneConfig(num_boxes_range=(3, 1))
