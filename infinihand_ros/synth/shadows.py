"""Shadows the hands and arms cast on the scene: shadow maps seen from each light.

Each light that can cast (the directional light from far along its direction, a lamp from its
position) sees the hand and forearm capsules and the palms in a small depth map; every scene
point the camera sees is looked up in each map, and behind an occluder it loses that light's
share of its shading. Shadows are computed per image block and blurred into a penumbra.
"""

from dataclasses import dataclass
from typing import Final
from typing import Protocol

import cv2
from infinihand_ros.core.geometry import project_points
from infinihand_ros.core.raster import SUBPIXEL_BITS
from infinihand_ros.mano import capsules as caps
from infinihand_ros.mano.capsules import PARALLEL_EPS
from infinihand_ros.synth.scene import Lighting
from infinihand_ros.synth.sensor import upsampled
import numpy as np

#: Shadows the hands and arms cast on the scene: side (px) of the shadow maps seen from each
#: light, how far the directional light's map is from the bodies (m), the depth margin before
#: a point counts as behind an occluder (m), the penumbra (m at the receiver, Gaussian sigma)
#: and the image block (px) at whose centres shadows are computed (then interpolated).
SHADOW_MAP_PX: Final = 64
SUN_DISTANCE_M: Final = 20.0
SHADOW_BIAS_M: Final = 0.01
PENUMBRA_M: Final = 0.008
SHADOW_STEP: Final = 4


class ShadowFrame(Protocol):
    """What shadows read of a frame in progress (the renderer's camera-frame buffers)."""

    rgb: np.ndarray  # (H, W, 3) uint8, darkened in place
    inv_depth: np.ndarray  # (H, W) float32 inverse z depth (1/m), 0 where empty
    ray_x: np.ndarray  # (W,) float32 x / z of each column's pixel ray
    ray_y: np.ndarray  # (H,) float32 y / z of each row's pixel ray
    k: np.ndarray  # (3, 3) intrinsics
    rot_cw: np.ndarray  # (3, 3) world-to-camera rotation
    t_cw: np.ndarray  # (3,) world-to-camera translation (m)
    near_m: float  # near clipping plane (m)


class Casters(Protocol):
    """The bodies that cast shadows: hand capsules first, then their arms', and the palms."""

    capsules: caps.CapsuleSet  # camera frame
    palms: caps.PalmSet  # camera frame
    num_hand: int  # how many of the capsules belong to hands


@dataclass(frozen=True)
class _LightView:
    """The bodies seen from a light: its pinhole camera and their depth in it.

    Attributes:
        lamp: True for the point lamp, False for the directional light (seen from afar).
        rotation: (3, 3) world -> light camera.
        origin: (3,) the camera's centre (world, m).
        k: (3, 3) the light camera's intrinsics (``SHADOW_MAP_PX`` square image).
        depth: (SHADOW_MAP_PX, SHADOW_MAP_PX) float32 depth of the nearest body (m; inf: none).

    """

    lamp: bool
    rotation: np.ndarray
    origin: np.ndarray
    k: np.ndarray
    depth: np.ndarray


def _light_views(frame: ShadowFrame, bodies: Casters, lighting: Lighting) -> list[_LightView]:
    """Depth maps of the bodies seen from each light that can cast their shadows.

    The lamp and the directional light (a pinhole far along its direction), each aimed at the
    bodies' bounding sphere; a light inside it or off casts none.
    """
    to_world = frame.rot_cw.T
    # Casters: the hands and their forearms (an upper arm's shadow falls out of view).
    index = np.arange(len(bodies.capsules.radii))
    casters = bodies.capsules.subset((index < bodies.num_hand)
                                     | ((index - bodies.num_hand) % 3 != 2))
    points = np.concatenate([casters.starts, casters.ends])
    centre_cam = 0.5 * (points.min(axis=0) + points.max(axis=0))
    radius = float(np.linalg.norm(points - centre_cam, axis=1).max()) + float(casters.radii.max())
    centre = to_world @ (centre_cam - frame.t_cw)
    views = []
    for lamp, factor, origin in (
            (True, lighting.lamp, np.asarray(lighting.lamp_world, np.float64)),
            (False, lighting.diffuse,
             centre + SUN_DISTANCE_M * np.asarray(lighting.direction_world, np.float64))):
        distance = float(np.linalg.norm(centre - origin))
        if factor <= 0.0 or distance <= radius * 1.05:
            continue
        forward = (centre - origin) / distance
        side = np.cross(forward, [0.0, 0.0, 1.0] if abs(forward[2]) < 0.9 else [1.0, 0.0, 0.0])
        side /= np.linalg.norm(side)
        rot = np.stack([side, np.cross(forward, side), forward])  # world -> light camera
        half_angle = np.arcsin(radius / distance)
        focal = 0.5 * SHADOW_MAP_PX / np.tan(half_angle)
        k = np.array([[focal, 0.0, SHADOW_MAP_PX / 2.0], [0.0, focal, SHADOW_MAP_PX / 2.0],
                      [0.0, 0.0, 1.0]])
        # The light camera <- the frame's camera, through the world.
        rotation = rot @ to_world
        translation = rot @ (-to_world @ frame.t_cw - origin)
        depth = _shadow_map(casters, bodies.palms, rotation, translation, k)
        views.append(_LightView(lamp, rot, origin, k, depth))
    return views


def _shadow_map(capsules: caps.CapsuleSet, palms: caps.PalmSet, rotation: np.ndarray,
                translation: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Depth (m) of the nearest body in a light's square image; inf where none.

    Capsules are drawn as thick lines and palms as filled polygons, far to near, each at its
    nearest depth: coarse outlines, as the shadows they cast are blurred.
    """
    size = SHADOW_MAP_PX
    depth = np.full((size, size), np.inf, np.float32)
    scale = 1 << SUBPIXEL_BITS
    move = (lambda points: points @ rotation.T + translation)
    project = (lambda points: np.round(project_points(points, k) * scale).astype(np.int32))
    ends = np.stack([move(capsules.starts), move(capsules.ends)], axis=1)  # (N, 2, 3)
    radii = capsules.radii.max(axis=1)
    nearest = ends[..., 2].min(axis=1) - radii
    widths = np.maximum(1, np.round(2.0 * k[0, 0] * radii / ends[..., 2].mean(axis=1)))
    lines = np.flatnonzero(nearest > 0.0)
    pixels = project(ends[lines])
    shapes = [(nearest[i], pixels[row], int(widths[i])) for row, i in enumerate(lines)]
    for index in range(len(palms.sides)):
        rim = move(palms.centres[index] + palms.polygons[index] @ palms.axes[index, :2])
        closest = rim[:, 2].min() - palms.half_thickness[index]
        if closest > 0.0:
            shapes.append((closest, project(rim), 0))
    for closest, points, width in sorted(shapes, key=lambda shape: -shape[0]):
        if width:
            cv2.line(depth, tuple(points[0]), tuple(points[1]), float(closest), width,
                     cv2.LINE_8, SUBPIXEL_BITS)
        else:
            cv2.fillConvexPoly(depth, points, float(closest), cv2.LINE_8, SUBPIXEL_BITS)
    return depth


def cast_shadows(frame: ShadowFrame, bodies: Casters, lighting: Lighting) -> None:
    """Darken the scene where the hands and arms keep a light from it (soft shadow maps).

    Each scene point seen (at the centre of every ``SHADOW_STEP`` block) is looked up in each
    light's depth map of the bodies; behind an occluder it loses that light's share of its
    shading (Lambert, the normal from the depth map), softened over ``PENUMBRA_M``.
    """
    if len(bodies.capsules.radii) == 0 or not (frame.inv_depth > 0).any():
        return
    views = _light_views(frame, bodies, lighting)
    if not views:
        return
    height, width = frame.inv_depth.shape
    step = SHADOW_STEP
    rows = np.minimum(np.arange(-(-height // step)) * step + step // 2, height - 1)
    cols = np.minimum(np.arange(-(-width // step)) * step + step // 2, width - 1)
    inv_depth = frame.inv_depth[rows][:, cols].astype(np.float64)
    seen = inv_depth > 0
    depth = np.where(seen, 1.0 / np.maximum(inv_depth, PARALLEL_EPS), 0.0)
    cam = np.stack([frame.ray_x[cols][None, :] * depth, frame.ray_y[rows][:, None] * depth,
                    depth], axis=-1)
    world = (cam - frame.t_cw) @ frame.rot_cw
    normals = np.cross(np.gradient(world, axis=1), np.gradient(world, axis=0))
    normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), PARALLEL_EPS)
    eye = -frame.rot_cw.T @ frame.t_cw
    normals *= np.where(np.sum(normals * (eye - world), axis=-1, keepdims=True) < 0, -1.0, 1.0)
    sun, lamp = lighting.direct_terms(world, normals)
    total = lighting.ambient + sun + lamp
    lost = np.zeros(depth.shape)
    for light in views:
        local = (world - light.origin) @ light.rotation.T
        u, v = np.round(project_points(local, light.k)).astype(int).transpose(2, 0, 1)
        inside = (seen & (local[..., 2] > frame.near_m) & (u >= 0) & (u < SHADOW_MAP_PX)
                  & (v >= 0) & (v < SHADOW_MAP_PX))
        occluder = np.full(depth.shape, np.inf)
        occluder[inside] = light.depth[v[inside], u[inside]]
        lost += (local[..., 2] > occluder + SHADOW_BIAS_M) * (lamp if light.lamp else sun)
    if not lost.any():
        return
    keep = 1.0 - np.where(seen, lost / np.maximum(total, PARALLEL_EPS), 0.0)
    median_depth = max(float(np.median(depth[seen])), PARALLEL_EPS)
    sigma = float(np.clip(frame.k[0, 0] * PENUMBRA_M / median_depth / step, 0.5, 8.0))
    keep = upsampled(cv2.GaussianBlur(keep.astype(np.float32), (0, 0), sigma), step, height,
                     width)
    frame.rgb[:] = np.clip(frame.rgb * keep[..., None] + 0.5, 0, 255).astype(np.uint8)
