"""Fast z-buffer renderer of a synthetic scene and two capsule hands (numpy + OpenCV, one core).

Scene surfaces are planar textured quads: each front-facing quad is clipped against the near plane,
its texture is warped into the bounding rectangle of its projection with one
``cv2.warpPerspective`` (plane-to-image homography), and its inverse depth, an affine function of
the pixel (u, v) on a plane, is z-tested against an inverse-depth buffer inside its polygon. Hands
are capsules (bones, plus palm fillers) intersected analytically with the pixel rays of each
capsule's projected bounding box, Lambert-shaded from the capsule normal and z-tested in the same
buffer, so hands occlude each other and are occluded by the table and boxes.

Pixel convention (OpenCV): pixel (column i, row j) shows the ray through image point
(u, v) = (i, j), i.e. ``K^-1 [i, j, 1]`` in the OpenCV optical camera frame (x right, y down,
z forward). Depth is z along the optical axis, in metres.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import cv2
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.raster import SUBPIXEL_BITS
from infinihand_ros.core.validation import as_array
from infinihand_ros.mano import capsules as caps
from infinihand_ros.synth.scene import Lighting
from infinihand_ros.synth.scene import Scene
import numpy as np
from scipy.special import ndtri

#: Number of noise levels (one random byte per pixel and channel picks a Gaussian quantile).
NOISE_LEVELS: Final = 256
#: Owner of pixels that show no hand capsule.
NO_CAPSULE: Final = -1


@dataclass(frozen=True)
class HandGeometry:
    """One hand as capsules around its skeleton.

    Attributes:
        side: 0 left, 1 right.
        joints_world: (21, 3) joints in the OpenPose order, world frame, metres.
        radii: (21,) capsule radius at each joint (m); a bone uses the mean of its two joints.
        skin_rgb: skin colour (R, G, B) in 0-255.

    """

    side: int
    joints_world: np.ndarray
    radii: np.ndarray
    skin_rgb: tuple[int, int, int]

    def __post_init__(self) -> None:
        if self.side not in SIDES:
            raise InputError(f'HandGeometry.side must be 0 (left) or 1 (right), got {self.side!r}')
        as_array(self.joints_world, 'HandGeometry.joints_world', (NUM_JOINTS, 3))
        radii = as_array(self.radii, 'HandGeometry.radii', (NUM_JOINTS,))
        if np.any(radii <= 0):
            raise InputError(f'HandGeometry.radii must be positive metres, got min {radii.min()}')
        if len(self.skin_rgb) != 3:
            raise InputError(
                f'HandGeometry.skin_rgb must be 3 ints (R, G, B), got {self.skin_rgb}')


@dataclass(frozen=True)
class RenderOptions:
    """Image degradations and clipping.

    Attributes:
        noise_sigma: std of additive Gaussian image noise (uint8 units); 0 disables it.
        motion_blur_px: length of a linear motion blur (pixels); below 1 disables it.
        motion_blur_angle_rad: direction of the blur in the image (0 = along +u).
        noise_seed: seed of the noise (draw it per frame from the sequence's generator).
        near_m: near clipping plane (m).

    """

    noise_sigma: float = 2.0
    motion_blur_px: float = 0.0
    motion_blur_angle_rad: float = 0.0
    noise_seed: int = 0
    near_m: float = 0.05

    def __post_init__(self) -> None:
        if self.noise_sigma < 0 or self.motion_blur_px < 0:
            raise InputError(f'RenderOptions: noise_sigma={self.noise_sigma} and motion_blur_px='
                             f'{self.motion_blur_px} must be >= 0')
        if self.near_m <= 0:
            raise InputError(f'RenderOptions.near_m must be > 0 metres, got {self.near_m}')


@dataclass
class RenderOutput:
    """One rendered frame.

    Attributes:
        rgb: (H, W, 3) uint8 image.
        depth: (H, W) float32 z depth (m), +inf where nothing was drawn.
        hand_masks: (2, H, W) bool visible pixels of the left (0) and right (1) hand.

    """

    rgb: np.ndarray
    depth: np.ndarray
    hand_masks: np.ndarray


@dataclass
class _Frame:
    """Buffers and pixel rays of a frame in progress (camera frame quantities)."""

    rgb: np.ndarray
    inv_depth: np.ndarray
    ray_x: np.ndarray
    ray_y: np.ndarray
    k: np.ndarray
    rot_cw: np.ndarray
    t_cw: np.ndarray
    near_m: float


def _new_frame(k: np.ndarray, T_world_cam: np.ndarray, width: int, height: int,
               near_m: float) -> _Frame:
    rot_cw = T_world_cam[:3, :3].T
    return _Frame(
        rgb=np.zeros((height, width, 3), np.uint8),
        inv_depth=np.zeros((height, width), np.float32),
        ray_x=((np.arange(width) - k[0, 2]) / k[0, 0]).astype(np.float32),
        ray_y=((np.arange(height) - k[1, 2]) / k[1, 1]).astype(np.float32),
        k=k, rot_cw=rot_cw, t_cw=-rot_cw @ T_world_cam[:3, 3], near_m=near_m)


def _clip_near(points: np.ndarray, near_m: float) -> np.ndarray:
    """Clip a convex polygon (N, 3) in the camera frame to z >= near (Sutherland-Hodgman)."""
    out = []
    count = len(points)
    for i in range(count):
        cur, nxt = points[i], points[(i + 1) % count]
        cur_in, nxt_in = cur[2] >= near_m, nxt[2] >= near_m
        if cur_in:
            out.append(cur)
        if cur_in != nxt_in:
            out.append(cur + (near_m - cur[2]) / (nxt[2] - cur[2]) * (nxt - cur))
    return np.array(out).reshape(-1, 3)


def _draw_quad(frame: _Frame, texture: np.ndarray, corners: np.ndarray, normal: np.ndarray,
               plane_offset: float) -> None:
    """Z-test and draw one front-facing textured quad.

    Args:
        frame: the frame in progress.
        texture: the quad's RGB uint8 texture.
        corners: (4, 3) camera-frame corners: origin, +u, +u+v, +v.
        normal: (3,) camera-frame unit normal of the visible side.
        plane_offset: ``normal . X`` for points X on the plane (< 0 when facing the camera).

    """
    poly = _clip_near(corners, frame.near_m)
    if len(poly) < 3:
        return
    k = frame.k
    u = k[0, 0] * poly[:, 0] / poly[:, 2] + k[0, 2]
    v = k[1, 1] * poly[:, 1] / poly[:, 2] + k[1, 2]
    height, width = frame.inv_depth.shape
    rect = caps.pixel_rect(u, v, width, height)
    if rect is None:
        return
    x0, y0, x1, y1 = rect
    coef = normal / plane_offset  # inverse depth = coef . (ray_x, ray_y, 1)
    inv_depth = (frame.ray_x[None, x0:x1] * np.float32(coef[0])
                 + frame.ray_y[y0:y1, None] * np.float32(coef[1]) + np.float32(coef[2]))
    mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
    scale = 1 << SUBPIXEL_BITS
    pts = np.round(np.stack([u - x0, v - y0], axis=1) * scale).astype(np.int32)
    cv2.fillConvexPoly(mask, pts, 1, cv2.LINE_8, SUBPIXEL_BITS)
    visible = mask.view(bool) & (inv_depth > frame.inv_depth[y0:y1, x0:x1])
    if not visible.any():
        return
    visible = visible.view(np.uint8)
    # Warp only the bounding box of the visible pixels (near quads are drawn first).
    bx, by, bw, bh = cv2.boundingRect(visible)
    visible = visible[by:by + bh, bx:bx + bw]
    inv_depth = inv_depth[by:by + bh, bx:bx + bw]
    x0, y0, x1, y1 = x0 + bx, y0 + by, x0 + bx + bw, y0 + by + bh
    tex_h, tex_w = texture.shape[:2]
    edge_u = (corners[1] - corners[0]) / tex_w
    edge_v = (corners[3] - corners[0]) / tex_h
    # Texel (x, y) centre -> camera point, then -> pixel of the rectangle (a homography).
    texel_to_cam = np.stack([edge_u, edge_v, corners[0] + 0.5 * (edge_u + edge_v)], axis=1)
    shift = np.array([[1.0, 0.0, -x0], [0.0, 1.0, -y0], [0.0, 0.0, 1.0]])
    warped = cv2.warpPerspective(texture, shift @ k @ texel_to_cam, (x1 - x0, y1 - y0),
                                 flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    # cv2.copyTo writes into the numpy views in place (much faster than a masked np.copyto).
    cv2.copyTo(warped, visible, frame.rgb[y0:y1, x0:x1])
    cv2.copyTo(inv_depth, visible, frame.inv_depth[y0:y1, x0:x1])


def _draw_scene(frame: _Frame, scene: Scene) -> None:
    """Cull back faces, then draw the quads near to far (far quads warp only what shows)."""
    corners = scene.quad_corners @ frame.rot_cw.T + frame.t_cw
    normals = scene.quad_normals @ frame.rot_cw.T
    offsets = np.einsum('qi,qi->q', normals, corners[:, 0])
    front = np.flatnonzero(offsets < 0.0)
    distances = np.linalg.norm(corners[front].mean(axis=1), axis=1)
    for index in front[np.argsort(distances)]:
        _draw_quad(frame, scene.quads[index].texture, corners[index], normals[index],
                   float(offsets[index]))


def _draw_capsules(frame: _Frame, capsules: caps.CapsuleSet) -> np.ndarray:
    """Z-test and draw capsules into the inverse-depth buffer; return each pixel's capsule.

    Returns:
        (H, W) int16 index of the capsule seen at each pixel (``NO_CAPSULE`` for none).

    """
    height, width = frame.inv_depth.shape
    owner = np.full((height, width), NO_CAPSULE, np.int16)
    ray_x = frame.ray_x.astype(np.float64)
    ray_y = frame.ray_y.astype(np.float64)
    rects = caps.capsule_rects(capsules, frame.k, frame.near_m, width, height)
    for index, (x0, y0, x1, y1) in enumerate(rects.tolist()):
        if x0 >= x1 or y0 >= y1:
            continue
        depth = caps.ray_capsule_depth(ray_x[None, x0:x1], ray_y[y0:y1, None], capsules, index)
        with np.errstate(invalid='ignore', divide='ignore'):
            inv_depth = np.where(depth >= frame.near_m, 1.0 / depth, 0.0).astype(np.float32)
        target = frame.inv_depth[y0:y1, x0:x1]
        nearer = inv_depth > target
        cv2.copyTo(inv_depth, nearer.view(np.uint8), target)
        owner[y0:y1, x0:x1][nearer] = index
    return owner


def _shade_hands(frame: _Frame, capsules: caps.CapsuleSet, owner: np.ndarray,
                 hands: Sequence[HandGeometry], lighting: Lighting) -> None:
    """Colour the visible hand pixels: skin times Lambert shading from the capsule normals."""
    rows, cols = np.nonzero(owner != NO_CAPSULE)
    if rows.size == 0:
        return
    ids = owner[rows, cols]
    z = 1.0 / frame.inv_depth[rows, cols].astype(np.float64)
    points = np.stack([frame.ray_x[cols] * z, frame.ray_y[rows] * z, z], axis=1)
    normals = caps.surface_normals(points, capsules, ids)
    # Row vectors: p_world = (p_cam - t_cw) @ rot_cw.
    shade = lighting.shade((points - frame.t_cw) @ frame.rot_cw, normals @ frame.rot_cw)
    skins = np.zeros((len(SIDES), 3))
    for hand in hands:
        skins[hand.side] = np.asarray(hand.skin_rgb, np.float64) * lighting.tint
    colours = shade[:, None] * skins[capsules.sides[ids]]
    frame.rgb[rows, cols] = np.clip(colours, 0, 255).astype(np.uint8)


def _hand_masks(capsules: caps.CapsuleSet, owner: np.ndarray) -> np.ndarray:
    """Visible pixels (2, H, W) bool of the left and right hands from the capsule owners."""
    side_of = np.append(capsules.sides, -1)  # index NO_CAPSULE (-1) maps to side -1
    pixel_side = side_of[owner]
    return np.stack([pixel_side == side for side in SIDES])


def _degrade(rgb: np.ndarray, options: RenderOptions) -> np.ndarray:
    """Apply motion blur and Gaussian noise to a uint8 image."""
    if options.motion_blur_px >= 1.0:
        size = int(np.ceil(options.motion_blur_px)) | 1
        kernel = np.zeros((size, size), np.float32)
        half = 0.5 * (options.motion_blur_px - 1.0)
        centre = (size - 1) / 2.0
        dx = half * np.cos(options.motion_blur_angle_rad)
        dy = half * np.sin(options.motion_blur_angle_rad)
        scale = 1 << SUBPIXEL_BITS
        p0 = (int(round((centre - dx) * scale)), int(round((centre - dy) * scale)))
        p1 = (int(round((centre + dx) * scale)), int(round((centre + dy) * scale)))
        cv2.line(kernel, p0, p1, 1.0, 1, cv2.LINE_AA, SUBPIXEL_BITS)
        rgb = cv2.filter2D(rgb, -1, kernel / kernel.sum(), borderType=cv2.BORDER_REPLICATE)
    if options.noise_sigma > 0:
        # Gaussian noise by inverse-CDF lookup of random bytes (256 quantiles, rounded to
        # integers), several times faster than drawing normal floats.
        rng = np.random.default_rng(options.noise_seed)
        quantiles = ndtri((np.arange(NOISE_LEVELS) + 0.5) / NOISE_LEVELS)
        table = np.round(quantiles * options.noise_sigma).astype(np.int16)
        noise_bytes = np.frombuffer(rng.bytes(rgb.size), np.uint8).reshape(rgb.shape)
        rgb = cv2.add(rgb, cv2.LUT(noise_bytes, table), dtype=cv2.CV_8U)
    return rgb


def render_frame(scene: Scene, K: np.ndarray, T_world_cam: np.ndarray, width: int, height: int,
                 hands: Sequence[HandGeometry], options: RenderOptions) -> RenderOutput:
    """Render one frame of a scene with hands.

    Args:
        scene: the room (world frame of ``scene``).
        K: (3, 3) pinhole intrinsics (pixels, OpenCV convention, see the module docstring).
        T_world_cam: (4, 4) camera-to-world pose, OpenCV optical camera frame.
        width: image width (pixels).
        height: image height (pixels).
        hands: at most one hand per side.
        options: noise, blur and clipping.

    Returns:
        RGB image, z depth (+inf where empty) and visible-hand masks (left, right).

    Raises:
        InputError: on a bad K, pose, image size or two hands of the same side.

    """
    k = as_array(K, 'K', (3, 3))
    pose = as_array(T_world_cam, 'T_world_cam', (4, 4))
    if k[0, 0] <= 0 or k[1, 1] <= 0:
        raise InputError(f'K: focal lengths must be positive, got fx={k[0, 0]}, fy={k[1, 1]}')
    if int(width) <= 0 or int(height) <= 0:
        raise InputError(f'image size must be positive, got {width}x{height}')
    sides = [hand.side for hand in hands]
    if len(set(sides)) != len(sides):
        raise InputError(f'hands: at most one hand per side, got sides {sides}')
    frame = _new_frame(k, pose, int(width), int(height), options.near_m)
    _draw_scene(frame, scene)
    capsules = caps.build_capsule_set(
        [(np.asarray(hand.joints_world, np.float64) @ frame.rot_cw.T + frame.t_cw,
          np.asarray(hand.radii, np.float64), hand.side) for hand in hands])
    owner = _draw_capsules(frame, capsules)
    _shade_hands(frame, capsules, owner, hands, scene.lighting)
    depth = np.full(frame.inv_depth.shape, np.inf, np.float32)
    np.divide(1.0, frame.inv_depth, out=depth, where=frame.inv_depth > 0)
    return RenderOutput(_degrade(frame.rgb, options), depth, _hand_masks(capsules, owner))
