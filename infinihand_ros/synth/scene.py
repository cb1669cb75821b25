"""Procedural rooms for synthetic sequences: floor, walls, ceiling, a table and boxes on it.

World frame of a scene (gravity aligned): z up, the floor is the plane z = 0, the room's centre is
above the origin, x and y are horizontal with the table's long side along x. Every surface is a
planar textured quad (``TexturedQuad``) whose texture already carries the scene's lighting (ambient
+ one directional light + one ceiling lamp, Lambert per texel, baked when the scene is made), so
rendering only warps textures. Everything is drawn from one ``numpy.random.Generator``.
"""

from dataclasses import dataclass
from functools import cached_property
from typing import Final

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.synth import textures
import numpy as np

#: Texture resolution (pixels per metre) of the room (seen from metres away) and of the table,
#: legs and boxes (seen from under a metre, where a texel should stay about a pixel); sides are
#: bounded.
ROOM_TEXTURE_PX_PER_M: Final = 160.0
OBJECT_TEXTURE_PX_PER_M: Final = 400.0
MAX_TEXTURE_PX: Final = 1024
#: Lighting is evaluated on this many grid points per side of each quad, then interpolated.
SHADE_GRID: Final = 9
#: Table legs: square section side and inset from the table corners (m).
LEG_SIDE_M: Final = 0.05
LEG_INSET_M: Final = 0.06
#: Boxes keep this distance from the table edges and from each other (m).
BOX_MARGIN_M: Final = 0.04
#: Tries to place each box without overlap before giving up on it.
BOX_PLACEMENT_TRIES: Final = 30
#: Ceiling lamp hangs this far below the ceiling and at most this far from the table centre
#: horizontally (m).
LAMP_DROP_M: Final = 0.3
LAMP_OFFSET_M: Final = 0.8
#: Elevation of the directional light above the horizon (degrees).
SUN_ELEVATION_RANGE_DEG: Final = (35.0, 80.0)
#: Per-channel jitter of the light colour (multiplier 1 +- jitter).
LIGHT_TINT_JITTER: Final = 0.08


@dataclass(frozen=True)
class SceneConfig:
    """Ranges the scene generator draws from (metres unless stated).

    Attributes:
        room_half_extent_range_m: half width/depth of the room interior.
        room_height_range_m: floor-to-ceiling height.
        table_size_range_m: ((min length, max length), (min width, max width)) of the top, x by y.
        table_height_range_m: height of the table top surface above the floor.
        table_thickness_m: thickness of the table top.
        table_clearance_m: free floor between the table and every wall (room for the camera).
        num_boxes_range: inclusive range of the number of boxes on the table.
        box_size_range_m: side lengths of the boxes (each side drawn independently).
        ambient_range: ambient light factor.
        diffuse_range: directional light factor.
        lamp_range: ceiling lamp factor (see ``Lighting.lamp``).

    """

    room_half_extent_range_m: tuple[float, float] = (2.3, 3.5)
    room_height_range_m: tuple[float, float] = (2.5, 3.0)
    table_size_range_m: tuple[tuple[float, float], tuple[float, float]] = ((1.0, 1.8), (0.6, 1.0))
    table_height_range_m: tuple[float, float] = (0.72, 0.78)
    table_thickness_m: float = 0.04
    table_clearance_m: float = 1.3
    num_boxes_range: tuple[int, int] = (2, 4)
    box_size_range_m: tuple[float, float] = (0.06, 0.28)
    ambient_range: tuple[float, float] = (0.35, 0.55)
    diffuse_range: tuple[float, float] = (0.3, 0.55)
    lamp_range: tuple[float, float] = (0.4, 1.0)

    def __post_init__(self) -> None:
        lo, hi = self.room_half_extent_range_m
        max_table = max(self.table_size_range_m[0][1], self.table_size_range_m[1][1])
        if lo <= 0 or hi < lo or lo < max_table / 2 + self.table_clearance_m:
            raise ConfigError(
                f'room_half_extent_range_m={self.room_half_extent_range_m} must be increasing and '
                f'leave table_clearance_m={self.table_clearance_m} around a table up to '
                f'{max_table} m long; enlarge the room or shrink the table')
        if self.num_boxes_range[0] < 0 or self.num_boxes_range[1] < self.num_boxes_range[0]:
            raise ConfigError(f'num_boxes_range={self.num_boxes_range} must be an increasing '
                              'pair of non-negative counts')
        if self.table_height_range_m[0] <= self.table_thickness_m:
            raise ConfigError(f'table_height_range_m={self.table_height_range_m} must exceed '
                              f'table_thickness_m={self.table_thickness_m}')


@dataclass(frozen=True)
class OrientedBox:
    """A box rotated about the world z axis.

    Attributes:
        center: (3,) centre in the world frame (m).
        half_extents: (3,) half sizes along the box's own x, y, z axes (m).
        yaw_rad: rotation about world z of the box's x axis.

    """

    center: np.ndarray
    half_extents: np.ndarray
    yaw_rad: float = 0.0

    def axes(self) -> np.ndarray:
        """Return the box axes as rows (3, 3) in the world frame."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])

    def contains(self, points: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """Return which world points (N, 3) lie inside the box grown by ``margin_m`` (N,) bool."""
        local = (np.asarray(points, np.float64).reshape(-1, 3) - self.center) @ self.axes().T
        return np.all(np.abs(local) <= self.half_extents + margin_m, axis=1)


@dataclass(frozen=True)
class Lighting:
    """Scene light: ambient + one directional light + one point lamp (Lambert).

    Attributes:
        ambient: ambient factor.
        diffuse: directional light factor.
        direction_world: (3,) unit vector from surfaces towards the directional light.
        lamp_world: (3,) position of the point lamp (m).
        lamp: point lamp factor; its Lambert term falls off as 1 / (1 + d^2), d in metres.
        tint: (3,) RGB multiplier of the light colour.

    """

    ambient: float
    diffuse: float
    direction_world: np.ndarray
    lamp_world: np.ndarray
    lamp: float
    tint: np.ndarray

    def shade(self, points: np.ndarray, normals: np.ndarray, wrap: float = 0.0) -> np.ndarray:
        """Shading factor (N,) of world points (N, 3) with unit normals (N, 3).

        Lambert for ``wrap`` 0; a positive ``wrap`` lets the directional light reach past the
        terminator, ``(n . l + wrap) / (1 + wrap)``, as light scattered under skin does.
        """
        direct, lamp = self.direct_terms(points, normals, wrap)
        return self.ambient + direct + lamp

    def direct_terms(self, points: np.ndarray, normals: np.ndarray,
                     wrap: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Shares (N,) of the directional light and of the lamp in ``shade``."""
        direct = np.clip((normals @ self.direction_world + wrap) / (1.0 + wrap), 0.0, None)
        to_lamp = self.lamp_world - points
        dist = np.linalg.norm(to_lamp, axis=-1)
        lamp = np.clip(np.sum(normals * to_lamp, axis=-1) / dist, 0.0, None) / (1.0 + dist ** 2)
        return self.diffuse * direct, self.lamp * lamp


@dataclass(frozen=True)
class TexturedQuad:
    """A planar parallelogram with a texture; visible from the side its normal points to.

    World point of texture coordinate (s, t) in [0, 1]^2: ``origin + s edge_u + t edge_v``; the
    texture's columns run along ``edge_u`` and its rows along ``edge_v``. Seen from the visible
    side, ``edge_u`` points right and ``edge_v`` down, so the texture is not mirrored.

    Attributes:
        origin: (3,) world corner at texture pixel (0, 0) (m).
        edge_u: (3,) world edge along the texture's x axis (m).
        edge_v: (3,) world edge along the texture's y axis (m).
        texture: RGB uint8 (h, w, 3), lighting baked in.
        name: what the surface is (for debugging).

    """

    origin: np.ndarray
    edge_u: np.ndarray
    edge_v: np.ndarray
    texture: np.ndarray
    name: str = ''

    @property
    def normal(self) -> np.ndarray:
        """Return the visible side's unit normal, ``edge_v x edge_u`` normalised, shape (3,)."""
        n = np.cross(self.edge_v, self.edge_u)
        return n / np.linalg.norm(n)

    def corners(self) -> np.ndarray:
        """Return the four world corners, shape (4, 3), in polygon order."""
        o, u, v = self.origin, self.edge_u, self.edge_v
        return np.stack([o, o + u, o + u + v, o + v])


@dataclass(frozen=True)
class Scene:
    """A generated room.

    Attributes:
        quads: every visible surface.
        room: interior of the room (the camera must stay inside).
        table: the table as a solid box from the floor to its top surface.
        boxes: boxes standing on the table.
        lighting: the light used for the baked textures (and for hands).

    """

    quads: tuple[TexturedQuad, ...]
    room: OrientedBox
    table: OrientedBox
    boxes: tuple[OrientedBox, ...]
    lighting: Lighting

    @property
    def obstacles(self) -> tuple[OrientedBox, ...]:
        """Solid things the camera must stay out of: the table (floor to top) and the boxes."""
        return (self.table, *self.boxes)

    @cached_property
    def quad_corners(self) -> np.ndarray:
        """Return the world corners (Q, 4, 3) of every quad, in polygon order (cached)."""
        return np.stack([quad.corners() for quad in self.quads])

    @cached_property
    def quad_normals(self) -> np.ndarray:
        """Return the unit normals (Q, 3) of the visible sides of every quad (cached)."""
        return np.stack([quad.normal for quad in self.quads])

    @property
    def table_top_z(self) -> float:
        """Height of the table top surface (m)."""
        return float(self.table.center[2] + self.table.half_extents[2])

    @property
    def table_top_center(self) -> np.ndarray:
        """Centre (3,) of the table top surface in the world frame (m)."""
        return np.array([self.table.center[0], self.table.center[1], self.table_top_z])


def _face_frames(box: OrientedBox,
                 inward: bool) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Return (origin, edge_u, edge_v) of the six faces of ``box``, normals out or in.

    Side faces get ``edge_v`` pointing down so text-like marks stand upright.
    """
    axes = box.axes()
    frames = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            outward = sign * axes[axis]
            normal = -outward if inward else outward
            if axis == 2:
                a = axes[0]
                b = np.cross(a, normal)
            else:
                b = -axes[2]
                a = np.cross(normal, b)
            half_a = np.abs(axes @ a) @ box.half_extents
            half_b = np.abs(axes @ b) @ box.half_extents
            centre = box.center + outward * box.half_extents[axis]
            frames.append((centre - half_a * a - half_b * b, 2.0 * half_a * a, 2.0 * half_b * b))
    return frames


def _make_quad(rng: np.random.Generator, frame: tuple[np.ndarray, np.ndarray, np.ndarray],
               lighting: Lighting, name: str,
               colours: tuple[np.ndarray, np.ndarray] | None = None,
               px_per_m: float = OBJECT_TEXTURE_PX_PER_M) -> TexturedQuad:
    """Texture and light one face."""
    origin, edge_u, edge_v = frame
    size = [int(np.clip(np.linalg.norm(e) * px_per_m, textures.MIN_TEXTURE_PX,
                        MAX_TEXTURE_PX)) for e in (edge_u, edge_v)]
    texture = textures.make_texture(rng, size[1], size[0], colours)
    s, t = np.meshgrid(np.linspace(0, 1, SHADE_GRID), np.linspace(0, 1, SHADE_GRID))
    points = origin + s[..., None] * edge_u + t[..., None] * edge_v
    normal = np.cross(edge_v, edge_u)
    normal = np.broadcast_to(normal / np.linalg.norm(normal), points.shape)
    shade = lighting.shade(points.reshape(-1, 3), normal.reshape(-1, 3)).reshape(s.shape)
    shade_rgb = shade[..., None] * lighting.tint
    return TexturedQuad(origin, edge_u, edge_v, textures.shade_texture(texture, shade_rgb), name)


def _box_quads(rng: np.random.Generator, box: OrientedBox, lighting: Lighting, name: str,
               keep: tuple[int, ...] = (0, 1, 2, 3, 4, 5)) -> list[TexturedQuad]:
    """Textured faces of a solid box (face order: +x, -x, +y, -y, +z, -z)."""
    colours = (textures.random_colour(rng), textures.random_colour(rng))
    frames = _face_frames(box, inward=False)
    return [_make_quad(rng, frames[i], lighting, f'{name}_{i}', colours) for i in keep]


def _sample_lighting(rng: np.random.Generator, config: SceneConfig, room: OrientedBox,
                     table_top: np.ndarray) -> Lighting:
    """Draw a random light: a sky-ish directional light and a lamp above the table."""
    elevation = np.radians(rng.uniform(*SUN_ELEVATION_RANGE_DEG))
    azimuth = rng.uniform(0.0, 2.0 * np.pi)
    direction = np.array([np.cos(elevation) * np.cos(azimuth),
                          np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
    ceiling = room.center[2] + room.half_extents[2]
    lamp = np.array([table_top[0] + rng.uniform(-LAMP_OFFSET_M, LAMP_OFFSET_M),
                     table_top[1] + rng.uniform(-LAMP_OFFSET_M, LAMP_OFFSET_M),
                     ceiling - LAMP_DROP_M])
    tint = 1.0 + rng.uniform(-LIGHT_TINT_JITTER, LIGHT_TINT_JITTER, 3)
    return Lighting(rng.uniform(*config.ambient_range), rng.uniform(*config.diffuse_range),
                    direction, lamp, rng.uniform(*config.lamp_range), tint)


def _sample_boxes(rng: np.random.Generator, config: SceneConfig,
                  table: OrientedBox) -> list[OrientedBox]:
    """Place non-overlapping boxes on the table top (bounding circles kept apart)."""
    top_z = table.center[2] + table.half_extents[2]
    count = int(rng.integers(config.num_boxes_range[0], config.num_boxes_range[1] + 1))
    boxes: list[OrientedBox] = []
    for _ in range(count):
        half = rng.uniform(*config.box_size_range_m, 3) / 2.0
        radius = float(np.hypot(half[0], half[1]))
        room_xy = table.half_extents[:2] - radius - BOX_MARGIN_M
        if np.any(room_xy <= 0):
            continue
        for _ in range(BOX_PLACEMENT_TRIES):
            xy = table.center[:2] + rng.uniform(-room_xy, room_xy)
            if all(np.hypot(*(xy - b.center[:2])) > radius + np.hypot(*b.half_extents[:2])
                   + BOX_MARGIN_M for b in boxes):
                boxes.append(OrientedBox(np.array([xy[0], xy[1], top_z + half[2]]), half,
                                         float(rng.uniform(0.0, np.pi))))
                break
    return boxes


def _table_quads(rng: np.random.Generator, table_top: OrientedBox, lighting: Lighting,
                 top_z_floor: float) -> list[TexturedQuad]:
    """Faces of the table top slab and its four legs (legs without top and bottom faces)."""
    quads = _box_quads(rng, table_top, lighting, 'table')
    leg_height = top_z_floor
    offsets = table_top.half_extents[:2] - LEG_INSET_M
    colours = (textures.random_colour(rng), textures.random_colour(rng))
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            centre = np.array([table_top.center[0] + sx * offsets[0],
                               table_top.center[1] + sy * offsets[1], leg_height / 2.0])
            leg = OrientedBox(centre, np.array([LEG_SIDE_M / 2, LEG_SIDE_M / 2, leg_height / 2]))
            quads += [_make_quad(rng, f, lighting, 'leg', colours)
                      for f in _face_frames(leg, inward=False)[:4]]
    return quads


def make_scene(rng: np.random.Generator, config: SceneConfig | None = None) -> Scene:
    """Generate a random room with a table and boxes, textured and lit.

    Args:
        rng: random generator (the only source of randomness).
        config: ranges to draw from; defaults to ``SceneConfig()``.

    Returns:
        The scene, world frame z up with the floor at z = 0 (see the module docstring).

    """
    config = config or SceneConfig()
    half_xy = rng.uniform(*config.room_half_extent_range_m, 2)
    height = rng.uniform(*config.room_height_range_m)
    room = OrientedBox(np.array([0.0, 0.0, height / 2]),
                       np.array([half_xy[0], half_xy[1], height / 2]))
    table_half = np.array([rng.uniform(*config.table_size_range_m[0]),
                           rng.uniform(*config.table_size_range_m[1])]) / 2.0
    slack = np.maximum(half_xy - table_half - config.table_clearance_m, 0.0)
    table_xy = rng.uniform(-slack, slack)
    top_z = rng.uniform(*config.table_height_range_m)
    thickness = config.table_thickness_m
    table_top = OrientedBox(np.array([table_xy[0], table_xy[1], top_z - thickness / 2]),
                            np.array([table_half[0], table_half[1], thickness / 2]))
    table = OrientedBox(np.array([table_xy[0], table_xy[1], top_z / 2]),
                        np.array([table_half[0], table_half[1], top_z / 2]))
    lighting = _sample_lighting(rng, config, room, np.array([*table_xy, top_z]))
    names = ('wall_px', 'wall_nx', 'wall_py', 'wall_ny', 'ceiling', 'floor')
    quads = [_make_quad(rng, frame, lighting, name, px_per_m=ROOM_TEXTURE_PX_PER_M)
             for frame, name in zip(_face_frames(room, inward=True), names)]
    quads += _table_quads(rng, table_top, lighting, top_z - thickness)
    boxes = _sample_boxes(rng, config, table)
    for index, box in enumerate(boxes):
        quads += _box_quads(rng, box, lighting, f'box{index}', keep=(0, 1, 2, 3, 4))
    return Scene(tuple(quads), room, table, tuple(boxes), lighting)
