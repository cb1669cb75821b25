"""Capsule hands: capsules around a skeleton, their joint radii and analytic ray-capsule hits.

A capsule is the set of points within ``radius`` of a segment (a cylinder with two hemispherical
caps). A hand is its 20 bones plus a few capsules across the palm, the thumb web and the thenar
eminence, so that it reads as a hand rather than a stick figure. Rays are those of pixels in the
OpenCV optical camera frame, ``(x, y, 1)`` (not normalised), so a ray parameter is directly the
z depth. The built-in
hand's surface is this one: the synthetic renderer draws it and the annotation masks of
``data/hand_masks.py`` are cut from it.
"""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.hand_conventions import JOINT_PARENTS
import numpy as np

#: Palm fillers: fractions along wrist -> MCP where a capsule runs across the palm.
PALM_FRACTIONS: Final = (0.3, 0.6)
#: MCP joints across the palm (index, middle, ring, pinky) and the thumb web (CMC, index MCP).
PALM_MCPS: Final = (5, 9, 13, 17)
THUMB_WEB: Final = (1, 5)
#: Below this squared sine (relative) between a ray and a capsule axis, the side is skipped.
PARALLEL_EPS: Final = 1e-12
#: Capsule radius (m) at the wrist, MCP, PIP, DIP and tip joints of the mean hand.
JOINT_RADII_M: Final = (0.024, 0.011, 0.0095, 0.0085, 0.0075)
#: The thumb is thicker: radius (m) at its CMC, MCP, IP joints and tip.
THUMB_RADII_M: Final = (0.016, 0.0125, 0.011, 0.0095)
#: The thenar eminence: a capsule from the wrist to the thumb's MCP, this thick (m).
THENAR: Final = (0, 2)
THENAR_RADIUS_M: Final = 0.014


@dataclass(frozen=True)
class CapsuleSet:
    """Capsules of one or more hands in the camera frame (N capsules).

    Attributes:
        starts: (N, 3) segment starts (m).
        ends: (N, 3) segment ends (m).
        radii: (N,) radii (m).
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


def joint_radii(betas: np.ndarray) -> np.ndarray:
    """Capsule radius (21,) in metres of each joint (OpenPose order) of a hand of shape ``betas``.

    ``JOINT_RADII_M`` (wrist, then MCP, PIP, DIP, tip of each finger) scaled with the hand's
    overall size, ``exp(0.05 * beta_0)``.
    """
    size = float(np.exp(0.05 * np.asarray(betas, np.float64)[0]))
    return np.array([JOINT_RADII_M[0], *THUMB_RADII_M, *list(JOINT_RADII_M[1:]) * 4]) * size


def hand_capsules(joints: np.ndarray,
                  radii: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Build the capsules of a hand: the 20 bones plus fillers across the palm and the thumb web.

    A bone's radius is the mean of its two joints' radii; palm fillers use the mean radius of
    the wrist and the four MCPs.

    Args:
        joints: (21, 3) joints, OpenPose order, any frame (m).
        radii: (21,) joint radii (m).

    Returns:
        (starts (N, 3), ends (N, 3), radii (N,)) of the capsules.

    """
    pairs = [(parent, child) for child, parent in enumerate(JOINT_PARENTS) if parent >= 0]
    starts = [joints[p] for p, _ in pairs]
    ends = [joints[c] for _, c in pairs]
    caps_r = [0.5 * (radii[p] + radii[c]) for p, c in pairs]
    palm_r = float(np.mean(radii[[0, *PALM_MCPS]]))
    for fraction in (*PALM_FRACTIONS, 1.0):
        across = joints[0] + fraction * (joints[list(PALM_MCPS)] - joints[0])
        starts += list(across[:-1])
        ends += list(across[1:])
        caps_r += [palm_r] * (len(PALM_MCPS) - 1)
    starts.append(joints[THUMB_WEB[0]])
    ends.append(joints[THUMB_WEB[1]])
    caps_r.append(0.5 * (radii[THUMB_WEB[0]] + radii[THUMB_WEB[1]]))
    starts.append(joints[THENAR[0]])
    ends.append(joints[THENAR[1]])
    caps_r.append(THENAR_RADIUS_M * radii[0] / JOINT_RADII_M[0])
    return np.array(starts), np.array(ends), np.array(caps_r)


def build_capsule_set(hands: list[tuple[np.ndarray, np.ndarray, int]]) -> CapsuleSet:
    """Capsules of several hands given as (joints (21, 3), radii (21,), side) in one frame.

    Caps are deduplicated per hand: a cap is skipped when an earlier capsule already has a cap
    at exactly that point with a radius at least as large (it would be hidden inside it).
    """
    parts: list[tuple] = []
    for joints, radii, side in hands:
        starts, ends, caps_r = hand_capsules(joints, radii)
        drawn: dict[bytes, float] = {}
        for start, end, radius in zip(starts, ends, caps_r):
            caps = [drawn.get(point.tobytes(), -1.0) < radius for point in (start, end)]
            for point, cap in zip((start, end), caps):
                if cap:
                    drawn[point.tobytes()] = radius
            parts.append((start, end, radius, caps[0], caps[1], side))
    if not parts:
        empty = np.zeros((0, 3))
        return CapsuleSet(empty, empty, np.zeros(0), np.zeros(0, bool), np.zeros(0, bool),
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
    lo = np.minimum(capsules.starts, capsules.ends) - capsules.radii[:, None]
    hi = np.maximum(capsules.starts, capsules.ends) + capsules.radii[:, None]
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

    Args:
        rx: (1, w) float64 ray x components, ``(u - cx) / fx``.
        ry: (h, 1) float64 ray y components, ``(v - cy) / fy``.
        capsules: camera-frame capsules.
        index: which capsule.

    Returns:
        (h, w) float64 depths; NaN where the ray misses (negative behind the camera).

    """
    start, end = capsules.starts[index], capsules.ends[index]
    radius = float(capsules.radii[index])
    rdrd = (rx * rx + 1.0) + ry * ry
    axis = end - start
    axis2 = axis @ axis
    ax_o = -(axis @ start)  # axis . (origin - start)
    ax_d = (axis[0] * rx + axis[2]) + axis[1] * ry
    d_o = -((start[0] * rx + start[2]) + start[1] * ry)  # ray . (origin - start)
    # Side: |(p - start) x axis|^2 = r^2 |axis|^2 with p = t d, a quadratic in t.
    qa = axis2 * rdrd - ax_d * ax_d
    qb = axis2 * d_o - ax_o * ax_d
    disc = qb * qb - qa * (axis2 * (start @ start - radius * radius) - ax_o * ax_o)
    with np.errstate(invalid='ignore', divide='ignore'):
        np.sqrt(disc, out=disc)
        depth = (-qb - disc) / qa
        along = ax_o + depth * ax_d
        depth[(qa <= PARALLEL_EPS * axis2) | (along <= 0.0) | (along >= axis2)] = np.nan
        if capsules.start_caps[index]:
            np.fmin(depth, _ray_sphere(rx, ry, rdrd, start, radius), out=depth)
        if capsules.end_caps[index]:
            np.fmin(depth, _ray_sphere(rx, ry, rdrd, end, radius), out=depth)
    return depth


def surface_normals(points: np.ndarray, capsules: CapsuleSet, ids: np.ndarray) -> np.ndarray:
    """Outward unit normals (N, 3) at points (N, 3) on the surfaces of capsules ``ids`` (N,)."""
    starts = capsules.starts[ids]
    axes = capsules.ends[ids] - starts
    rel = points - starts
    along = np.einsum('ij,ij->i', rel, axes) / np.maximum(np.einsum('ij,ij->i', axes, axes),
                                                          PARALLEL_EPS)
    normals = rel - np.clip(along, 0.0, 1.0)[:, None] * axes
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), PARALLEL_EPS)
