"""Capsule hands: a palm slab and capsules around a skeleton, and their analytic ray hits.

A capsule here is a round cone: the convex hull of two spheres, one at each end of a segment,
whose radii may differ (a cone tangent to both, closed by the spheres; equal radii give a cylinder
with two hemispherical caps). Bones are round cones from one joint's sphere to the next, so a
finger is a sphere-mesh (Tkach et al., SIGGRAPH Asia 2016): a smooth surface that tapers from
knuckle to tip, continuous across its joints, and deformed by the joints alone. A hand is a flat
palm slab, capsules around the 15 bones of the fingers and the thumb,
knuckle bumps and a thenar bulge. The slab is a polygon in the palm's middle plane (from the
wrist to the MCP row) grown by the palm's half thickness all round: two flat faces plus capsules
along the polygon's edges, so its rim is round. Rays are those of pixels in the OpenCV optical
camera frame, ``(x, y, 1)`` (not normalised), so a ray parameter is directly the z depth. The
built-in hand's surface is this one: the synthetic renderer draws it and the annotation masks
of ``data/hand_masks.py`` are cut from it.
"""

from dataclasses import dataclass
from dataclasses import fields
from typing import Final

from infinihand_ros.core.hand_conventions import JOINT_PARENTS
from infinihand_ros.core.hand_conventions import LEFT
import numpy as np

#: MCP joints across the palm (index, middle, ring, pinky).
PALM_MCPS: Final = (5, 9, 13, 17)
#: Joints the palm slab moves with: the wrist and the MCPs.
PALM_JOINTS: Final = (0, *PALM_MCPS)
#: Child joints of the bones drawn as capsules (every bone but the five from the wrist), in
#: bone order; a hand's first capsules are these bones.
BONE_CHILDREN: Final = tuple(child for child, parent in enumerate(JOINT_PARENTS) if parent > 0)
#: Below this squared sine (relative) between a ray and a capsule axis, the side is skipped.
PARALLEL_EPS: Final = 1e-12
#: Capsule radius (m) at the wrist, MCP, PIP, DIP and tip joints of the mean hand (the wrist's
#: sets the hand's size).
JOINT_RADII_M: Final = (0.024, 0.011, 0.0095, 0.0085, 0.0075)
#: The thumb is thicker: radius (m) at its CMC, MCP, IP joints and tip.
THUMB_RADII_M: Final = (0.016, 0.0125, 0.011, 0.0095)
#: Palm slab of the mean hand (m): half thickness, offset of its middle plane from the joints
#: towards the palm side, and its polygon: half widths at the wrist (thumb side, little-finger
#: side), how far short of the MCP row it stops, how far inside the index and pinky MCPs its
#: corners lie, and how far its little-finger edge bulges out (hypothenar).
PALM_HALF_THICKNESS_M: Final = 0.0125
PALM_OFFSET_M: Final = 0.003
PALM_WRIST_HALF_WIDTHS_M: Final = (0.010, 0.014)
PALM_ROW_BACK_M: Final = 0.008
PALM_SIDE_INSET_M: Final = 0.0035
HYPOTHENAR_BULGE_M: Final = 0.006
#: Knuckles: spheres at the MCPs moved towards the back of the hand (m), radius relative to the
#: MCP joint's.
KNUCKLE_BACK_M: Final = 0.004
KNUCKLE_SCALE: Final = 0.85
#: Thenar eminence: a capsule from this fraction of the way wrist -> thumb CMC to the middle of
#: the thumb's metacarpal, moved towards the palm side (m), this thick (m).
THENAR_START: Final = 0.4
THENAR_PALMAR_M: Final = 0.006
THENAR_RADIUS_M: Final = 0.013


@dataclass(frozen=True)
class CapsuleSet:
    """Capsules of one or more hands in the camera frame (N capsules).

    Attributes:
        starts: (N, 3) segment starts (m).
        ends: (N, 3) segment ends (m).
        radii: (N, 2) radius at the start and at the end (m).
        start_caps: (N,) bool, intersect the start cap (False where an earlier capsule of the
            same hand already has a cap at least as large at that point).
        end_caps: (N,) bool, same for the end cap.
        sides: (N,) int, hand side of each capsule (0 left, 1 right).

    """

    starts: np.ndarray
    ends: np.ndarray
    radii: np.ndarray
    start_caps: np.ndarray
    end_caps: np.ndarray
    sides: np.ndarray

    def subset(self, keep: np.ndarray) -> 'CapsuleSet':
        """Return the capsules that ``keep`` selects (a bool mask (N,) or indices)."""
        return CapsuleSet(*(getattr(self, field.name)[keep] for field in fields(self)))


def joint_radii(betas: np.ndarray) -> np.ndarray:
    """Capsule radius (21,) in metres of each joint (OpenPose order) of a hand of shape ``betas``.

    ``JOINT_RADII_M`` (wrist, then MCP, PIP, DIP, tip of each finger) scaled with the hand's
    overall size, ``exp(0.05 * beta_0)``.
    """
    size = float(np.exp(0.05 * np.asarray(betas, np.float64)[0]))
    return np.array([JOINT_RADII_M[0], *THUMB_RADII_M, *list(JOINT_RADII_M[1:]) * 4]) * size


@dataclass(frozen=True)
class PalmSet:
    """Flat faces of the palm slabs of one or more hands (H palms, P polygon corners).

    Attributes:
        centres: (H, 3) origin of each palm's middle plane (m).
        axes: (H, 3, 3) rows: towards the fingers, towards the thumb, towards the palm side.
        polygons: (H, P, 2) the slab's polygon (along, across) in that frame (m).
        half_thickness: (H,) distance of the faces from the middle plane (m).
        sides: (H,) int, hand side of each palm (0 left, 1 right).

    """

    centres: np.ndarray
    axes: np.ndarray
    polygons: np.ndarray
    half_thickness: np.ndarray
    sides: np.ndarray


def _unit(vector: np.ndarray) -> np.ndarray:
    return vector / max(float(np.linalg.norm(vector)), PARALLEL_EPS)


def palm_axes(joints: np.ndarray, side: int) -> np.ndarray:
    """Rows (3, 3): towards the fingers, towards the thumb, the palm's normal (palm side)."""
    along = _unit(joints[9] - joints[0])
    across = joints[5] - joints[17]
    across = _unit(across - (across @ along) * along)
    palm = np.cross(joints[5] - joints[0], joints[17] - joints[0])
    palm *= -1.0 if side == LEFT else 1.0
    normal = np.cross(along, across)
    return np.stack([along, across, normal if normal @ palm >= 0.0 else -normal])


def _palm(joints: np.ndarray, radii: np.ndarray,
          side: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Middle-plane origin (3,), axes (3, 3), polygon (P, 2) and half thickness of a palm."""
    scale = radii[0] / JOINT_RADII_M[0]
    axes = palm_axes(joints, side)
    local = (joints - joints[0]) @ axes.T
    index, middle, ring, pinky = (local[j, :2] for j in PALM_MCPS)
    back, inset = PALM_ROW_BACK_M * scale, PALM_SIDE_INSET_M * scale
    radial, ulnar = (width * scale for width in PALM_WRIST_HALF_WIDTHS_M)
    pinky_corner = pinky + [-back, inset]
    hypothenar = 0.5 * (pinky_corner + [0.0, -ulnar]) - [0.0, HYPOTHENAR_BULGE_M * scale]
    polygon = np.array([[0.0, -ulnar], hypothenar, pinky_corner, ring - [back, 0.0],
                        middle - [back, 0.0], index - [back, inset], [0.0, radial]])
    centre = joints[0] + PALM_OFFSET_M * scale * axes[2]
    return centre, axes, polygon, PALM_HALF_THICKNESS_M * scale


def hand_capsules(joints: np.ndarray, radii: np.ndarray,
                  side: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Build the capsules of a hand: finger bones, knuckles, thenar and the palm slab's rim.

    A bone runs from its parent joint's sphere to its child joint's (each joint's radius), so
    the finger tapers and two bones meet on the same sphere.

    Args:
        joints: (21, 3) joints, OpenPose order, any frame (m).
        radii: (21,) joint radii (m).
        side: 0 left, 1 right.

    Returns:
        (starts (N, 3), ends (N, 3), radii (N, 2)) of the capsules, the bones first
        (``BONE_CHILDREN``).

    """
    joints = np.asarray(joints, np.float64)
    radii = np.asarray(radii, np.float64)
    scale = radii[0] / JOINT_RADII_M[0]
    centre, axes, polygon, half = _palm(joints, radii, side)
    starts = [joints[JOINT_PARENTS[c]] for c in BONE_CHILDREN]
    ends = [joints[c] for c in BONE_CHILDREN]
    caps_r = [(radii[JOINT_PARENTS[c]], radii[c]) for c in BONE_CHILDREN]
    for mcp in PALM_MCPS:
        knuckle = joints[mcp] - KNUCKLE_BACK_M * scale * axes[2]
        starts.append(knuckle)
        ends.append(knuckle)
        caps_r.append((KNUCKLE_SCALE * radii[mcp],) * 2)
    palmar = THENAR_PALMAR_M * scale * axes[2]
    starts.append(joints[0] + THENAR_START * (joints[1] - joints[0]) + palmar)
    ends.append(0.5 * (joints[1] + joints[2]) + palmar)
    caps_r.append((THENAR_RADIUS_M * scale,) * 2)
    rim = centre + polygon @ axes[:2]
    starts += list(rim)
    ends += list(np.roll(rim, -1, axis=0))
    caps_r += [(half, half)] * len(rim)
    return np.array(starts), np.array(ends), np.array(caps_r)


def part_joint_weights(count: int) -> np.ndarray:
    """Weights (count, 21) of the joints each of a hand's ``count`` capsules moves with.

    In ``hand_capsules`` order: a bone moves with its two joints, a knuckle with its MCP, the
    thenar with the wrist and the thumb's first two joints, the palm rim with the wrist and the
    MCPs. Rows sum to one.
    """
    weights = np.zeros((count, len(JOINT_PARENTS)))
    for row, child in enumerate(BONE_CHILDREN):
        weights[row, [JOINT_PARENTS[child], child]] = 0.5
    knuckles = len(BONE_CHILDREN)
    for row, mcp in enumerate(PALM_MCPS, start=knuckles):
        weights[row, mcp] = 1.0
    thenar = knuckles + len(PALM_MCPS)
    weights[thenar, [0, 1, 2]] = 1.0 / 3.0
    weights[thenar + 1:, list(PALM_JOINTS)] = 1.0 / len(PALM_JOINTS)
    return weights


def build_palm_set(hands: list[tuple[np.ndarray, np.ndarray, int]]) -> PalmSet:
    """Palm faces of several hands given as (joints (21, 3), radii (21,), side) in one frame."""
    palms = [_palm(np.asarray(j, np.float64), np.asarray(r, np.float64), side)
             for j, r, side in hands]
    if not palms:
        return PalmSet(np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 0, 2)), np.zeros(0),
                       np.zeros(0, int))
    columns = list(zip(*palms))
    return PalmSet(np.array(columns[0]), np.array(columns[1]), np.array(columns[2]),
                   np.array(columns[3]), np.array([side for _, _, side in hands]))


def build_capsule_set(hands: list[tuple[np.ndarray, np.ndarray, int]]) -> CapsuleSet:
    """Capsules of several hands given as (joints (21, 3), radii (21,), side) in one frame.

    Caps are deduplicated per hand: a cap is skipped when an earlier capsule already has a cap
    at exactly that point with a radius at least as large (it would be hidden inside it).
    """
    parts: list[tuple] = []
    for joints, radii, side in hands:
        starts, ends, caps_r = hand_capsules(joints, radii, side)
        drawn: dict[bytes, float] = {}
        for start, end, ends_r in zip(starts, ends, caps_r):
            caps = [drawn.get(point.tobytes(), -1.0) < radius
                    for point, radius in zip((start, end), ends_r)]
            for point, radius, cap in zip((start, end), ends_r, caps):
                if cap:
                    drawn[point.tobytes()] = radius
            parts.append((start, end, ends_r, caps[0], caps[1], side))
    if not parts:
        empty = np.zeros((0, 3))
        return CapsuleSet(empty, empty, np.zeros((0, 2)), np.zeros(0, bool), np.zeros(0, bool),
                          np.zeros(0, int))
    columns = list(zip(*parts))
    return CapsuleSet(np.array(columns[0]), np.array(columns[1]), np.array(columns[2]),
                      np.array(columns[3], bool), np.array(columns[4], bool),
                      np.array(columns[5], int))


def pixel_rect(u: np.ndarray, v: np.ndarray, width: int,
               height: int) -> tuple[int, int, int, int] | None:
    """Pixel rectangle (x0, y0, x1, y1), end-exclusive, covering image points; None if empty."""
    x0, x1 = max(0, int(np.floor(u.min()))), min(width, int(np.ceil(u.max())) + 1)
    y0, y1 = max(0, int(np.floor(v.min()))), min(height, int(np.ceil(v.max())) + 1)
    return None if x0 >= x1 or y0 >= y1 else (x0, y0, x1, y1)


def capsule_rects(capsules: CapsuleSet, k: np.ndarray, near_m: float, width: int,
                  height: int) -> np.ndarray:
    """Pixel rectangles (N, 4) int (x0, y0, x1, y1), end-exclusive, covering each capsule's image.

    Projects each capsule's axis-aligned bounding box; a box that crosses the near plane gets
    the whole image and one behind it (or out of view) gets an empty rectangle (x0 >= x1).
    """
    reach = capsules.radii.max(axis=1)[:, None]
    lo = np.minimum(capsules.starts, capsules.ends) - reach
    hi = np.maximum(capsules.starts, capsules.ends) + reach
    depth = np.maximum(np.stack([lo[:, 2], hi[:, 2]], axis=1), near_m)[:, None, :]
    ratios = np.stack([lo[:, :2], hi[:, :2]], axis=2)[..., None] / depth[..., None, :]
    ratios = ratios.reshape(len(lo), 2, 4)
    focal = np.array([k[0, 0], k[1, 1]])
    centre = np.array([k[0, 2], k[1, 2]])
    low = np.floor(focal * ratios.min(axis=2) + centre)
    high = np.ceil(focal * ratios.max(axis=2) + centre) + 1
    rects = np.concatenate([low, high], axis=1)
    rects[lo[:, 2] <= near_m] = (0, 0, width, height)
    rects = np.clip(rects, 0, [width, height, width, height]).astype(int)
    rects[hi[:, 2] <= near_m] = 0
    return rects


def _ray_sphere(rx: np.ndarray, ry: np.ndarray, rdrd: np.ndarray, centre: np.ndarray,
                radius: float) -> np.ndarray:
    """First z depth where rays (rx, ry, 1) hit a sphere (NaN where they miss)."""
    d_dot_c = (centre[0] * rx + centre[2]) + centre[1] * ry
    disc = d_dot_c * d_dot_c
    disc -= rdrd * (centre @ centre - radius * radius)
    np.sqrt(disc, out=disc)
    d_dot_c -= disc
    d_dot_c /= rdrd
    return d_dot_c


def ray_capsule_depth(rx: np.ndarray, ry: np.ndarray, capsules: CapsuleSet,
                      index: int) -> np.ndarray:
    """First z depth (h, w) where pixel rays (rx (1, w), ry (h, 1), 1) hit capsule ``index``.

    The round cone's side is the cone tangent to its two spheres: with ``y`` the position
    along the unit axis ``w`` from the start ``a`` and ``sin = (r_a - r_b) / |b - a|``, a
    point ``p`` lies on it where ``cos^2 |p - a|^2 - y^2 - r_a^2 + 2 r_a sin y = 0`` and
    ``r_a sin <= y <= |b - a| + r_b sin`` (between the circles where it touches the spheres);
    a quadratic in the ray parameter. The spheres close it.

    Args:
        rx: (1, w) float64 ray x components, ``(u - cx) / fx``.
        ry: (h, 1) float64 ray y components, ``(v - cy) / fy``.
        capsules: camera-frame capsules.
        index: which capsule.

    Returns:
        (h, w) float64 depths; NaN where the ray misses (negative behind the camera).

    """
    start, end = capsules.starts[index], capsules.ends[index]
    r_start, r_end = (float(r) for r in capsules.radii[index])
    rdrd = (rx * rx + 1.0) + ry * ry
    axis = end - start
    length = float(np.sqrt(axis @ axis))
    depth = np.full(np.broadcast(rx, ry).shape, np.nan)
    with np.errstate(invalid='ignore', divide='ignore'):
        if length > abs(r_start - r_end):  # else one sphere holds the other: no side
            unit = axis / length
            sin = (r_start - r_end) / length
            cos2 = 1.0 - sin * sin
            d_w = (unit[0] * rx + unit[2]) + unit[1] * ry
            o_w = -(unit @ start)  # w . (origin - start)
            d_o = -((start[0] * rx + start[2]) + start[1] * ry)  # ray . (origin - start)
            qa = cos2 * rdrd - d_w * d_w
            qb = cos2 * d_o - d_w * (o_w - r_start * sin)
            qc = cos2 * (start @ start) - o_w * o_w - r_start * r_start + 2.0 * r_start * sin * o_w
            root = np.sqrt(qb * qb - qa * qc)
            tiny = np.abs(qa) <= PARALLEL_EPS * rdrd
            for sign in (-1.0, 1.0):
                t = (-qb + sign * root) / qa
                along = o_w + t * d_w
                t[tiny | (along < r_start * sin) | (along > length + r_end * sin)] = np.nan
                np.fmin(depth, t, out=depth)
        if capsules.start_caps[index]:
            np.fmin(depth, _ray_sphere(rx, ry, rdrd, start, r_start), out=depth)
        if capsules.end_caps[index]:
            np.fmin(depth, _ray_sphere(rx, ry, rdrd, end, r_end), out=depth)
    return depth


def surface_normals(points: np.ndarray, capsules: CapsuleSet, ids: np.ndarray) -> np.ndarray:
    """Outward unit normals (N, 3) at points (N, 3) on the surfaces of capsules ``ids`` (N,).

    On a round cone the normal runs from the centre of the sphere that touches the surface at
    the point; that centre lies on the axis, ``tan`` times the point's distance from the axis
    before the point's own position along it, clipped to the segment.
    """
    starts = capsules.starts[ids]
    axes = capsules.ends[ids] - starts
    radii = capsules.radii[ids]
    rel = points - starts
    length = np.sqrt(np.maximum(np.einsum('ij,ij->i', axes, axes), PARALLEL_EPS))
    unit = axes / length[:, None]
    along = np.einsum('ij,ij->i', rel, unit)
    radial = np.linalg.norm(rel - along[:, None] * unit, axis=1)
    sin = np.clip((radii[:, 0] - radii[:, 1]) / length, -1.0, 1.0)
    centre = np.clip(along - sin / np.sqrt(np.maximum(1.0 - sin * sin, PARALLEL_EPS)) * radial,
                     0.0, length)
    normals = rel - centre[:, None] * unit
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), PARALLEL_EPS)


def palm_rects(palms: PalmSet, k: np.ndarray, near_m: float, width: int,
               height: int) -> np.ndarray:
    """Pixel rectangles (H, 4) int (x0, y0, x1, y1), end-exclusive, covering each palm's faces."""
    rects = np.zeros((len(palms.sides), 4), int)
    for index in range(len(palms.sides)):
        rim = palms.centres[index] + palms.polygons[index] @ palms.axes[index, :2]
        count = len(rim)
        edges = CapsuleSet(rim, np.roll(rim, -1, axis=0),
                           np.full((count, 2), palms.half_thickness[index]), np.ones(count, bool),
                           np.ones(count, bool), np.zeros(count, int))
        edge_rects = capsule_rects(edges, k, near_m, width, height)
        edge_rects = edge_rects[(edge_rects[:, 0] < edge_rects[:, 2])
                                & (edge_rects[:, 1] < edge_rects[:, 3])]
        if len(edge_rects):
            rects[index] = (*edge_rects[:, :2].min(axis=0), *edge_rects[:, 2:].max(axis=0))
    return rects


def _inside_polygon(x: np.ndarray, y: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Whether points (x, y) (any shape) lie inside a polygon (P, 2) (even-odd rule)."""
    inside = np.zeros(np.broadcast(x, y).shape, bool)
    for (x0, y0), (x1, y1) in zip(polygon, np.roll(polygon, -1, axis=0)):
        if x0 == x1:
            continue
        straddles = (x >= x0) != (x >= x1)
        inside ^= straddles & (y < y0 + (x - x0) * ((y1 - y0) / (x1 - x0)))
    return inside


def ray_palm_depth(rx: np.ndarray, ry: np.ndarray, palms: PalmSet, index: int) -> np.ndarray:
    """First z depth (h, w) where pixel rays (rx (1, w), ry (h, 1), 1) hit palm ``index``'s faces.

    Returns:
        (h, w) float64 depths; NaN where the ray misses both faces.

    """
    centre, axes = palms.centres[index], palms.axes[index]
    normal = axes[2]
    d_n = (normal[0] * rx + normal[2]) + normal[1] * ry
    d_along = (axes[0, 0] * rx + axes[0, 2]) + axes[0, 1] * ry
    d_across = (axes[1, 0] * rx + axes[1, 2]) + axes[1, 1] * ry
    depth = np.full(np.broadcast(rx, ry).shape, np.nan)
    with np.errstate(invalid='ignore', divide='ignore'):
        for sign in (1.0, -1.0):
            t = (centre @ normal + sign * palms.half_thickness[index]) / d_n
            hit = _inside_polygon(t * d_along - centre @ axes[0], t * d_across - centre @ axes[1],
                                  palms.polygons[index]) & (t > 0.0)
            np.fmin(depth, np.where(hit, t, np.nan), out=depth)
    return depth


def palm_normals(rays: np.ndarray, palms: PalmSet, ids: np.ndarray) -> np.ndarray:
    """Outward unit normals (N, 3) of the faces of palms ``ids`` (N,) seen along rays (N, 3)."""
    normals = palms.axes[ids, 2]
    facing = np.einsum('ij,ij->i', rays, normals)
    return normals * np.where(facing > 0.0, -1.0, 1.0)[:, None]
