"""Fast z-buffer renderer of a synthetic scene, two hands and their arms (numpy + OpenCV).

Scene surfaces are planar textured quads: each front-facing quad is clipped against the near plane,
its texture is warped into the bounding rectangle of its projection with one
``cv2.warpPerspective`` (plane-to-image homography), and its inverse depth, an affine function of
the pixel (u, v) on a plane, is z-tested against an inverse-depth buffer inside its polygon.
Hands are a palm slab (two flat faces and a round rim) with round cones around the finger bones
(tapering from joint to joint), knuckle spheres and a thenar capsule (``mano/capsules.py``),
intersected analytically with the pixel rays of each part's projected bounding box and z-tested in
the same buffer, so hands occlude each other and are occluded by the table and boxes. An arm (bare
forearm, sleeve, upper arm) can be attached to each hand; it occludes like a hand but is not part
of the hand's mask.

Skin is shaded from smoothed surface normals (the parts' normals averaged over a window about
half a finger wide, so the seams between the parts do not show), with wrap-around diffuse light,
a faint specular sheen and lighter palms; silhouettes are anti-aliased. Hands and forearms cast
soft shadows on the scene (a shadow map from each light, looked up per scene point, blurred).
Sensor effects follow: motion blur over the exposure, Gaussian noise and JPEG compression.

Pixel convention (OpenCV): pixel (column i, row j) shows the ray through image point
(u, v) = (i, j), i.e. ``K^-1 [i, j, 1]`` in the OpenCV optical camera frame (x right, y down,
z forward). Depth is z along the optical axis, in metres.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import cv2
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.geometry import project_points
from infinihand_ros.core.hand_conventions import FINGER_JOINTS
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.raster import SUBPIXEL_BITS
from infinihand_ros.core.validation import as_array
from infinihand_ros.mano import capsules as caps
from infinihand_ros.mano.capsules import PARALLEL_EPS
from infinihand_ros.synth.scene import Lighting
from infinihand_ros.synth.scene import Scene
import numpy as np
from scipy.special import ndtri

#: Number of noise levels (one random byte per pixel and channel picks a Gaussian quantile).
NOISE_LEVELS: Final = 256
#: Owner of pixels that show no hand or arm capsule.
NO_CAPSULE: Final = -1
#: Standard deviation (m at the surface) of the Gaussian that smooths the skin's normals.
NORMAL_SMOOTHING_M: Final = 0.006
#: Bounds (px) of that Gaussian's standard deviation in the image.
NORMAL_SMOOTHING_PX: Final = (0.5, 8.0)
#: Ambient occlusion of skin: neighbourhood (m, Gaussian sigma), depth below the local mean that
#: darkens fully (m), and how much (fraction of the light).
OCCLUSION_RADIUS_M: Final = 0.012
OCCLUSION_DEPTH_M: Final = 0.012
OCCLUSION_STRENGTH: Final = 0.6
#: Fingertip joints (OpenPose order), thumb first.
TIP_JOINTS: Final = tuple(joints[-1] for joints in FINGER_JOINTS)
#: Nails: colour blended into the skin, extra sheen, where they start along the last bone
#: (fraction from its base) and how far around the fingertip they reach (cosine to the nail's
#: normal).
NAIL_RGB: Final = (238, 208, 204)
NAIL_BLEND: Final = 0.6
NAIL_SHEEN: Final = 3.0
NAIL_START: Final = 0.35
NAIL_COS: Final = 0.55
#: Wrap-around of the diffuse light on skin (0: Lambert; light reaches past the terminator).
SKIN_WRAP: Final = 0.35
#: Specular sheen of skin (fraction of the directional light) and its Blinn-Phong exponent.
SKIN_SPECULAR: Final = 0.06
SKIN_SHININESS: Final = 12.0
#: How much of the wrist's motion the bare forearm, the sleeved forearm and the upper arm
#: follow during the exposure (the elbow and the shoulder move less).
ARM_WRIST_MOTION: Final = (1.0, 0.5, 0.25)
#: Motion blur: most samples of the exposure per image, the least motion (px) blurred, and the
#: block side (px) at whose centres the scene's motion is computed (then interpolated).
EXPOSURE_SAMPLES: Final = 8
MIN_BLUR_PX: Final = 0.5
FLOW_STEP: Final = 4
#: Shadows the hands and arms cast on the scene: side (px) of the shadow maps seen from each
#: light, how far the directional light's map is from the bodies (m), the depth margin before
#: a point counts as behind an occluder (m), the penumbra (m at the receiver, Gaussian sigma)
#: and the image block (px) at whose centres shadows are computed (then interpolated).
SHADOW_MAP_PX: Final = 64
SUN_DISTANCE_M: Final = 20.0
SHADOW_BIAS_M: Final = 0.01
PENUMBRA_M: Final = 0.008
SHADOW_STEP: Final = 4
#: Palms are lighter and pinker than the back of the hand: blend towards this colour.
PALM_RGB: Final = (242, 196, 180)
PALM_BLEND: Final = 0.3


@dataclass(frozen=True)
class ArmGeometry:
    """The arm of a hand: bare forearm, sleeved forearm and upper arm, one capsule each.

    Attributes:
        points_world: (4, 3) wrist, sleeve hem, elbow and shoulder, world frame (m).
        radii: (3,) radius of the bare forearm, the sleeved forearm and the upper arm (m).
        sleeve_rgb: sleeve colour (R, G, B) in 0-255.

    """

    points_world: np.ndarray
    radii: np.ndarray
    sleeve_rgb: tuple[int, int, int]

    def __post_init__(self) -> None:
        as_array(self.points_world, 'ArmGeometry.points_world', (4, 3))
        radii = as_array(self.radii, 'ArmGeometry.radii', (3,))
        if np.any(radii <= 0):
            raise InputError(f'ArmGeometry.radii must be positive metres, got {radii}')


@dataclass(frozen=True)
class HandGeometry:
    """One hand as capsules around its skeleton, and optionally its arm.

    Attributes:
        side: 0 left, 1 right.
        joints_world: (21, 3) joints in the OpenPose order, world frame, metres.
        radii: (21,) radius of the sphere at each joint (m); a bone tapers from its start
            joint's to its end joint's.
        skin_rgb: skin colour (R, G, B) in 0-255.
        arm: the arm attached at the wrist (not part of the hand's mask); None for none.

    """

    side: int
    joints_world: np.ndarray
    radii: np.ndarray
    skin_rgb: tuple[int, int, int]
    arm: ArmGeometry | None = None

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
        noise_seed: seed of the noise (draw it per frame from the sequence's generator).
        jpeg_quality: JPEG compression quality (1-100) applied last; 0 disables it.
        near_m: near clipping plane (m).

    """

    noise_sigma: float = 2.0
    noise_seed: int = 0
    jpeg_quality: int = 0
    near_m: float = 0.05

    def __post_init__(self) -> None:
        if self.noise_sigma < 0:
            raise InputError(f'RenderOptions.noise_sigma must be >= 0, got {self.noise_sigma}')
        if not 0 <= self.jpeg_quality <= 100:
            raise InputError(
                f'RenderOptions.jpeg_quality must be 0 (off) to 100, got {self.jpeg_quality}')
        if self.near_m <= 0:
            raise InputError(f'RenderOptions.near_m must be > 0 metres, got {self.near_m}')


@dataclass(frozen=True)
class Exposure:
    """Where the camera and the hands are when the shutter opens and when it closes.

    The image is the average over the exposure, the motion linear in between; the frame's own
    pose and joints (``render_frame``'s) are those of its middle, and its depth and masks.

    Attributes:
        T_world_cam: (2, 4, 4) camera-to-world poses at the opening and at the closing.
        joints_world: (2, H, 21, 3) joints of the H hands (``render_frame``'s order) at the
            opening and at the closing (world frame, m).

    """

    T_world_cam: np.ndarray
    joints_world: np.ndarray

    def __post_init__(self) -> None:
        as_array(self.T_world_cam, 'Exposure.T_world_cam', (2, 4, 4))
        joints = np.asarray(self.joints_world, np.float64)
        if joints.ndim != 4 or joints.shape[0] != 2 or joints.shape[2:] != (NUM_JOINTS, 3):
            raise InputError(f'Exposure.joints_world: expected shape (2, H, {NUM_JOINTS}, 3), '
                             f'got {joints.shape}')


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


def _draw_bodies(frame: _Frame, capsules: caps.CapsuleSet, palms: caps.PalmSet) -> np.ndarray:
    """Z-test and draw the capsules, then the palms' flat faces; return each pixel's owner.

    Returns:
        (H, W) int16: the capsule seen at each pixel, ``len(capsules.radii) + i`` for palm
        face ``i``, ``NO_CAPSULE`` for none.

    """
    height, width = frame.inv_depth.shape
    owner = np.full((height, width), NO_CAPSULE, np.int16)
    ray_x = frame.ray_x.astype(np.float64)
    ray_y = frame.ray_y.astype(np.float64)
    for intersect, bodies, rects, first in (
            (caps.ray_capsule_depth, capsules,
             caps.capsule_rects(capsules, frame.k, frame.near_m, width, height), 0),
            (caps.ray_palm_depth, palms,
             caps.palm_rects(palms, frame.k, frame.near_m, width, height), len(capsules.radii))):
        for index, (x0, y0, x1, y1) in enumerate(rects.tolist()):
            if x0 >= x1 or y0 >= y1:
                continue
            depth = intersect(ray_x[None, x0:x1], ray_y[y0:y1, None], bodies, index)
            with np.errstate(invalid='ignore', divide='ignore'):
                inv_depth = np.where(depth >= frame.near_m, 1.0 / depth, 0.0).astype(np.float32)
            target = frame.inv_depth[y0:y1, x0:x1]
            nearer = inv_depth > target
            cv2.copyTo(inv_depth, nearer.view(np.uint8), target)
            owner[y0:y1, x0:x1][nearer] = first + index
    return owner


@dataclass(frozen=True)
class _Bodies:
    """Capsules of the hands (first ``num_hand``) and of their arms, the hands' palm faces.

    Pixel owners number the capsules, then the palm faces (``len(capsules.radii)`` on).

    Attributes:
        capsules: camera-frame capsules, hand capsules first.
        palms: camera-frame palm faces of the hands.
        num_hand: how many of the capsules belong to hands (the rest are arms).
        hand_sides: (N + H,) side of the hand each owner belongs to (-1 for arms).
        albedo: (N + H, 3) colour (RGB 0-255) of each owner.
        palm_normals: (N + H, 3) camera-frame unit palm normal of each hand owner's hand (zeros
            for arms).
        nail_normals: (N + H, 3) camera-frame unit normal of the nail on a fingertip capsule
            (zeros for the other owners).
        hand_index: (N + H,) index (in ``render_frame``'s ``hands``) of the hand each owner
            moves with (its own, or the hand at the end of the arm).
        joint_weights: (N + H, 21) weights of that hand's joints each owner moves with.

    """

    capsules: caps.CapsuleSet
    palms: caps.PalmSet
    num_hand: int
    hand_sides: np.ndarray
    albedo: np.ndarray
    palm_normals: np.ndarray
    nail_normals: np.ndarray
    hand_index: np.ndarray
    joint_weights: np.ndarray


def _palm_normal(joints: np.ndarray, side: int) -> np.ndarray:
    """Return the unit normal (3,) of a hand's palm side from its wrist and index, pinky MCPs."""
    normal = np.cross(joints[5] - joints[0], joints[17] - joints[0])
    normal *= -1.0 if side == LEFT else 1.0
    return normal / max(np.linalg.norm(normal), PARALLEL_EPS)


def _nail_normals(joints: np.ndarray, palm: np.ndarray) -> np.ndarray:
    """Return the unit normals (5, 3) of the four fingers' nails (zeros for the thumb).

    A finger flexes about the axis across the palm, so its last bone's back side is that bone
    crossed with the axis, on the side of the back of the hand.
    """
    across = joints[5] - joints[17]
    across /= max(np.linalg.norm(across), PARALLEL_EPS)
    normals = np.zeros((len(TIP_JOINTS), 3))
    reference = np.cross(joints[9] - joints[0], across)
    sign = -1.0 if reference @ palm > 0 else 1.0
    for row, tip in enumerate(TIP_JOINTS[1:], start=1):
        normal = sign * np.cross(joints[tip] - joints[tip - 1], across)
        normals[row] = normal / max(np.linalg.norm(normal), PARALLEL_EPS)
    return normals


def _bodies(frame: _Frame, hands: Sequence[HandGeometry]) -> _Bodies:
    """Build the camera-frame capsules of the hands and arms, and their colours."""
    to_cam = (lambda points: np.asarray(points, np.float64) @ frame.rot_cw.T + frame.t_cw)
    joints = [to_cam(hand.joints_world) for hand in hands]
    described = [(j, np.asarray(hand.radii, np.float64), hand.side)
                 for j, hand in zip(joints, hands)]
    hand_set = caps.build_capsule_set(described)
    palms = caps.build_palm_set(described)
    albedo: list[np.ndarray] = []
    palm_rows: list[np.ndarray] = []
    nails: list[np.ndarray] = []
    movers: list[np.ndarray] = []
    weights: list[np.ndarray] = []
    for index, (j, hand) in enumerate(zip(joints, hands)):
        count = int(np.sum(hand_set.sides == hand.side))
        movers.append(np.full(count, index))
        weights.append(caps.part_joint_weights(count))
        palm = _palm_normal(j, hand.side)
        albedo.append(np.tile(np.asarray(hand.skin_rgb, np.float64), (count, 1)))
        palm_rows.append(np.tile(palm, (count, 1)))
        nail = np.zeros((count, 3))
        # Bone capsules come first (``caps.BONE_CHILDREN``).
        nail[[caps.BONE_CHILDREN.index(tip) for tip in TIP_JOINTS]] = _nail_normals(j, palm)
        nails.append(nail)
    parts = [hand_set]
    for index, hand in enumerate(hands):
        if hand.arm is None:
            continue
        movers.append(np.full(3, index))
        arm_weights = np.zeros((3, NUM_JOINTS))
        arm_weights[:, 0] = ARM_WRIST_MOTION
        weights.append(arm_weights)
        points = to_cam(hand.arm.points_world)
        radii = np.repeat(np.asarray(hand.arm.radii, float)[:, None], 2, axis=1)
        parts.append(caps.CapsuleSet(points[:3], points[1:], radii,
                                     np.array([False, True, True]), np.ones(3, bool),
                                     np.full(3, hand.side)))
        albedo.append(np.array([hand.skin_rgb, hand.arm.sleeve_rgb, hand.arm.sleeve_rgb],
                               np.float64))
        palm_rows.append(np.zeros((3, 3)))
        nails.append(np.zeros((3, 3)))
    capsules = caps.CapsuleSet(*(np.concatenate([getattr(part, name) for part in parts])
                                 for name in ('starts', 'ends', 'radii', 'start_caps',
                                              'end_caps', 'sides')))
    for index, (j, hand) in enumerate(zip(joints, hands)):
        albedo.append(np.asarray(hand.skin_rgb, np.float64)[None])
        palm_rows.append(_palm_normal(j, hand.side)[None])
        nails.append(np.zeros((1, 3)))
        movers.append(np.array([index]))
        palm_weights = np.zeros((1, NUM_JOINTS))
        palm_weights[0, list(caps.PALM_JOINTS)] = 1.0 / len(caps.PALM_JOINTS)
        weights.append(palm_weights)
    num_hand = len(hand_set.radii)
    sides = np.concatenate([hand_set.sides, np.full(len(capsules.radii) - num_hand, -1),
                            palms.sides])
    stack = (lambda rows, width=3: np.concatenate(rows) if rows else np.zeros((0, width)))
    return _Bodies(capsules, palms, num_hand, sides, stack(albedo), stack(palm_rows),
                   stack(nails), np.concatenate(movers) if movers else np.zeros(0, int),
                   stack(weights, NUM_JOINTS))


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


def _light_views(frame: _Frame, bodies: _Bodies, lighting: Lighting) -> list[_LightView]:
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


def _cast_shadows(frame: _Frame, bodies: _Bodies, lighting: Lighting) -> None:
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
    keep = _upsampled(cv2.GaussianBlur(keep.astype(np.float32), (0, 0), sigma), step, height,
                      width)
    frame.rgb[:] = np.clip(frame.rgb * keep[..., None] + 0.5, 0, 255).astype(np.uint8)


def _local_mean(values: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                sigma_px: float) -> np.ndarray:
    """Gaussian-weighted mean (N, C) of values (N, C) at pixels (rows, cols) over their neighbours.

    Normalised convolution: only the given pixels contribute, so the background does not enter
    the mean at the silhouette.
    """
    y0, y1 = int(rows.min()), int(rows.max()) + 1
    x0, x1 = int(cols.min()), int(cols.max()) + 1
    channels = values.shape[1]
    image = np.zeros((y1 - y0, x1 - x0, channels + 1), np.float32)
    image[rows - y0, cols - x0, :channels] = values
    image[rows - y0, cols - x0, channels] = 1.0
    image = cv2.GaussianBlur(image, (0, 0), sigma_px, borderType=cv2.BORDER_CONSTANT)
    picked = image[rows - y0, cols - x0].astype(np.float64)
    return picked[:, :channels] / np.maximum(picked[:, channels:], PARALLEL_EPS)


def _occlusion(z: np.ndarray, rows: np.ndarray, cols: np.ndarray, sigma_px: float) -> np.ndarray:
    """Ambient light kept (N,) at skin pixels: those deeper than their surroundings get less.

    A screen-space ambient occlusion: crevices between fingers, a palm behind curled fingers
    and the far side of an occluding edge lie behind the local mean depth.
    """
    mean = _local_mean(z[:, None], rows, cols, sigma_px)[:, 0]
    return 1.0 - OCCLUSION_STRENGTH * np.clip((z - mean) / OCCLUSION_DEPTH_M, 0.0, 1.0)


def _shade_bodies(frame: _Frame, bodies: _Bodies, owner: np.ndarray, lighting: Lighting) -> None:
    """Colour the visible hand and arm pixels (see the module docstring)."""
    rows, cols = np.nonzero(owner != NO_CAPSULE)
    if rows.size == 0:
        return
    ids = owner[rows, cols]
    z = 1.0 / frame.inv_depth[rows, cols].astype(np.float64)
    points = np.stack([frame.ray_x[cols] * z, frame.ray_y[rows] * z, z], axis=1)
    num_capsules = len(bodies.capsules.radii)
    normals = np.empty_like(points)
    on_capsule = ids < num_capsules
    normals[on_capsule] = caps.surface_normals(points[on_capsule], bodies.capsules,
                                               ids[on_capsule])
    normals[~on_capsule] = caps.palm_normals(points[~on_capsule], bodies.palms,
                                             ids[~on_capsule] - num_capsules)
    px_per_m = frame.k[0, 0] / float(np.median(z))
    sigma_px = float(np.clip(px_per_m * NORMAL_SMOOTHING_M, *NORMAL_SMOOTHING_PX))
    normals = _local_mean(normals, rows, cols, sigma_px)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), PARALLEL_EPS)
    # Row vectors: p_world = (p_cam - t_cw) @ rot_cw.
    shade = lighting.shade((points - frame.t_cw) @ frame.rot_cw, normals @ frame.rot_cw,
                           wrap=SKIN_WRAP)
    shade *= _occlusion(z, rows, cols, float(np.clip(px_per_m * OCCLUSION_RADIUS_M,
                                                     *NORMAL_SMOOTHING_PX)))
    light = frame.rot_cw @ lighting.direction_world
    half = light - points / np.linalg.norm(points, axis=1, keepdims=True)
    half /= np.maximum(np.linalg.norm(half, axis=1, keepdims=True), PARALLEL_EPS)
    sheen = (SKIN_SPECULAR * lighting.diffuse
             * np.clip(np.einsum('ij,ij->i', normals, half), 0.0, None) ** SKIN_SHININESS)
    facing = np.clip(np.einsum('ij,ij->i', normals, bodies.palm_normals[ids]), 0.0, 1.0)
    albedo = bodies.albedo[ids]
    albedo += (PALM_BLEND * facing)[:, None] * (np.asarray(PALM_RGB, np.float64) - albedo)
    nail = _on_nail(points, normals, bodies, ids)
    albedo[nail] += NAIL_BLEND * (np.asarray(NAIL_RGB, np.float64) - albedo[nail])
    sheen[nail] *= NAIL_SHEEN
    colours = (shade[:, None] * albedo + 255.0 * sheen[:, None]) * lighting.tint
    frame.rgb[rows, cols] = np.clip(colours, 0, 255).astype(np.uint8)
    _antialias(frame.rgb, owner != NO_CAPSULE, rows, cols)


def _on_nail(points: np.ndarray, normals: np.ndarray, bodies: _Bodies,
             ids: np.ndarray) -> np.ndarray:
    """Return which skin pixels (N,) lie on a nail: the back of a fingertip's outer part."""
    nail_normals = bodies.nail_normals[ids]
    candidates = np.flatnonzero(np.einsum('ij,ij->i', normals, nail_normals) >= NAIL_COS)
    starts = bodies.capsules.starts[ids[candidates]]
    axes = bodies.capsules.ends[ids[candidates]] - starts
    along = (np.einsum('ij,ij->i', points[candidates] - starts, axes)
             / np.maximum(np.einsum('ij,ij->i', axes, axes), PARALLEL_EPS))
    nail = np.zeros(len(ids), bool)
    nail[candidates[along >= NAIL_START]] = True
    return nail


def _antialias(rgb: np.ndarray, covered: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> None:
    """Soften the silhouette of the covered pixels: blur a one-pixel band on both sides of it."""
    height, width = covered.shape
    y0, y1 = max(int(rows.min()) - 2, 0), min(int(rows.max()) + 3, height)
    x0, x1 = max(int(cols.min()) - 2, 0), min(int(cols.max()) + 3, width)
    region = covered[y0:y1, x0:x1].view(np.uint8)
    kernel = np.ones((3, 3), np.uint8)
    band = cv2.dilate(region, kernel) != cv2.erode(region, kernel)
    blurred = cv2.GaussianBlur(rgb[y0:y1, x0:x1], (3, 3), 0.8)
    rgb[y0:y1, x0:x1][band] = blurred[band]


def _upsampled(coarse: np.ndarray, step: int, height: int, width: int) -> np.ndarray:
    """Bilinear upsampling of values at the centres of ``step``-pixel blocks to (height, width)."""
    blocks_y, blocks_x = coarse.shape[:2]
    return cv2.resize(coarse, (blocks_x * step, blocks_y * step),
                      interpolation=cv2.INTER_LINEAR)[:height, :width]


def _shifted_pixels(k: np.ndarray, u: np.ndarray, v: np.ndarray, depth: np.ndarray,
                    rot: np.ndarray, shift: np.ndarray,
                    travel: np.ndarray | None = None) -> np.ndarray:
    """Offsets (..., 2) from pixels (u, v) to where their points land in another camera.

    The points lie at ``depth`` along the pixels' rays in this camera; the other camera sees a
    point ``p`` at ``rot @ p + shift``, after it moved by ``travel`` ((..., 3), this camera's
    axes; None: static).
    """
    ray_x = (u - k[0, 2]) / k[0, 0]
    ray_y = (v - k[1, 2]) / k[1, 1]
    moved = np.stack([depth * (rot[i, 0] * ray_x + rot[i, 1] * ray_y + rot[i, 2]) + shift[i]
                      for i in range(3)], axis=-1)
    if travel is not None:
        moved += travel
    return project_points(moved, k) - np.stack(np.broadcast_arrays(u, v), axis=-1)


def _expose(frame: _Frame, bodies: _Bodies, owner: np.ndarray, hands: Sequence[HandGeometry],
            exposure: Exposure) -> None:
    """Blur the image with the motion of the camera and the hands during the exposure.

    Each pixel's surface point moves (with its hand's joints, or with the scene) from where it
    is at the shutter's opening to where it is at its closing, and the camera moves too; the
    pixel averages the image along that path. Hands and arms also smear over the pixels they
    sweep: a pixel shows them for the share of the exposure they cover it (``_moving_layer``).
    """
    height, width = owner.shape
    depth = np.full((height, width), 1e3, np.float32)  # empty pixels: far away
    np.divide(1.0, frame.inv_depth, out=depth, where=frame.inv_depth > 0)
    rot_wc, origin = frame.rot_cw.T, -frame.rot_cw.T @ frame.t_cw
    # The scene's paths vary smoothly: computed at the centre of every FLOW_STEP-pixel block and
    # interpolated; the hands' and arms' pixels exactly.
    step = FLOW_STEP
    blocks_y, blocks_x = -(-height // step), -(-width // step)
    centre_x = np.arange(blocks_x) * step + (step - 1) / 2.0
    centre_y = np.arange(blocks_y) * step + (step - 1) / 2.0
    coarse = np.empty((blocks_y, blocks_x, 4), np.float32)
    sampled = depth[np.minimum(centre_y.astype(int), height - 1)][
        :, np.minimum(centre_x.astype(int), width - 1)]
    moving = owner != NO_CAPSULE
    rows, cols = np.nonzero(moving)
    exact = np.empty((rows.size, 4), np.float32)
    if rows.size:
        mid = np.array([np.asarray(hand.joints_world, np.float64) for hand in hands])
        ids = owner[rows, cols]
    for end, (T_world_cam, joints) in enumerate(zip(exposure.T_world_cam, exposure.joints_world)):
        pose = np.asarray(T_world_cam, np.float64)
        rot = pose[:3, :3].T @ rot_wc  # this end's camera <- the frame's camera
        shift = pose[:3, :3].T @ (origin - pose[:3, 3])
        coarse[..., 2 * end:2 * end + 2] = _shifted_pixels(
            frame.k, centre_x[None, :], centre_y[:, None], sampled, rot, shift)
        if rows.size:
            part = np.einsum('pj,pjc->pc', bodies.joint_weights,
                             (np.asarray(joints, np.float64) - mid)[bodies.hand_index])
            travel = part[ids] @ pose[:3, :3]  # world motion, in this camera
            exact[:, 2 * end:2 * end + 2] = _shifted_pixels(
                frame.k, cols, rows, depth[rows, cols], rot, shift, travel)
    offsets = _upsampled(coarse, step, height, width)
    offsets[rows, cols] = exact
    path = offsets[..., 2:] - offsets[..., :2]
    longest = float(np.sqrt((path * path).sum(axis=-1).max()))
    if longest < MIN_BLUR_PX:
        return
    samples = int(min(EXPOSURE_SAMPLES, np.ceil(longest) + 1))
    pixels = np.stack(np.meshgrid(np.arange(width, dtype=np.float32),
                                  np.arange(height, dtype=np.float32)), axis=-1)
    layer = _moving_layer(moving, offsets, pixels) if rows.size else None
    grid = pixels - offsets[..., :2]
    total = np.zeros(frame.rgb.shape, np.float32)
    for fraction in np.linspace(0.0, 1.0, samples):
        where = cv2.scaleAdd(path, -fraction, grid)
        image = cv2.remap(frame.rgb, where[..., 0], where[..., 1], cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REPLICATE)
        cv2.accumulate(image, total)
        if layer is not None:
            y0, y1, x0, x1 = layer.region
            where = cv2.scaleAdd(layer.travel, -fraction, layer.start)
            alpha = cv2.remap(layer.cover, where[..., 0], where[..., 1], cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT)
            body = cv2.remap(frame.rgb, where[..., 0], where[..., 1], cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_REPLICATE)
            # Where the moving layer covers the pixel it shows the layer instead.
            total[y0:y1, x0:x1] += alpha[..., None] * (np.float32(body) - image[y0:y1, x0:x1])
    frame.rgb[:] = np.clip(total * np.float32(1.0 / samples) + 0.5, 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class _Layer:
    """The hands and arms as a layer sweeping over the image during the exposure.

    Attributes:
        region: (y0, y1, x0, x1) pixels they can reach.
        start: (h, w, 2) where each pixel of the region looks into the layer at the opening.
        travel: (h, w, 2) how far that moves until the closing (px).
        cover: (H, W) float32, 1 on the layer's pixels in the frame's image.

    """

    region: tuple[int, int, int, int]
    start: np.ndarray
    travel: np.ndarray
    cover: np.ndarray


def _moving_layer(moving: np.ndarray, offsets: np.ndarray, pixels: np.ndarray) -> _Layer | None:
    """Build the layer of the moving pixels; None when none moves a pixel or more.

    Moving pixels follow their own paths, the others within reach the mean path of the moving
    pixels around them (so the layer smears over them along its motion).
    """
    rows, cols = np.nonzero(moving)
    travel = offsets[rows, cols, 2:] - offsets[rows, cols, :2]
    reach = int(np.ceil(float(np.sqrt((travel * travel).sum(axis=-1).max())) / 2.0))
    if reach < 1:
        return None
    height, width = moving.shape
    y0, y1 = max(int(rows.min()) - reach, 0), min(int(rows.max()) + reach + 1, height)
    x0, x1 = max(int(cols.min()) - reach, 0), min(int(cols.max()) + reach + 1, width)
    inside = moving[y0:y1, x0:x1]
    cover = moving.astype(np.float32)
    size = 2 * reach + 1
    own = offsets[y0:y1, x0:x1]
    weight = cv2.blur(cover[y0:y1, x0:x1], (size, size), borderType=cv2.BORDER_CONSTANT)
    mean = cv2.blur(own * cover[y0:y1, x0:x1, None], (size, size),
                    borderType=cv2.BORDER_CONSTANT)
    mean /= np.maximum(weight, np.float32(1e-6))[..., None]
    carried = (~inside & (weight > 0.5 / size ** 2))[..., None]  # a moving pixel within reach
    paths = np.where(carried, mean, own)
    return _Layer((y0, y1, x0, x1), pixels[y0:y1, x0:x1] - paths[..., :2],
                  paths[..., 2:] - paths[..., :2], cover)


def _hand_masks(bodies: _Bodies, owner: np.ndarray) -> np.ndarray:
    """Visible pixels (2, H, W) bool of the left and right hands (arms excluded)."""
    pixel_side = np.append(bodies.hand_sides, -1)[owner]
    return np.stack([pixel_side == side for side in SIDES])


def degrade(rgb: np.ndarray, options: RenderOptions) -> np.ndarray:
    """Apply Gaussian noise and JPEG compression to a uint8 image."""
    if options.noise_sigma > 0:
        # Gaussian noise by inverse-CDF lookup of random bytes (256 quantiles, rounded to
        # integers), several times faster than drawing normal floats.
        rng = np.random.default_rng(options.noise_seed)
        quantiles = ndtri((np.arange(NOISE_LEVELS) + 0.5) / NOISE_LEVELS)
        table = np.round(quantiles * options.noise_sigma).astype(np.int16)
        noise_bytes = np.frombuffer(rng.bytes(rgb.size), np.uint8).reshape(rgb.shape)
        rgb = cv2.add(rgb, cv2.LUT(noise_bytes, table), dtype=cv2.CV_8U)
    if options.jpeg_quality > 0:
        bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
        _, encoded = cv2.imencode('.jpg', bgr, [cv2.IMWRITE_JPEG_QUALITY, options.jpeg_quality])
        rgb = cv2.cvtColor(cv2.imdecode(encoded, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    return rgb


def render_frame(scene: Scene, K: np.ndarray, T_world_cam: np.ndarray, width: int, height: int,
                 hands: Sequence[HandGeometry], options: RenderOptions,
                 exposure: Exposure | None = None) -> RenderOutput:
    """Render one frame of a scene with hands.

    Args:
        scene: the room (world frame of ``scene``).
        K: (3, 3) pinhole intrinsics (pixels, OpenCV convention, see the module docstring).
        T_world_cam: (4, 4) camera-to-world pose, OpenCV optical camera frame.
        width: image width (pixels).
        height: image height (pixels).
        hands: at most one hand per side.
        options: noise, JPEG and clipping.
        exposure: the camera's and the hands' motion while the shutter is open (motion blur);
            None for a still image.

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
    bodies = _bodies(frame, hands)
    _cast_shadows(frame, bodies, scene.lighting)
    owner = _draw_bodies(frame, bodies.capsules, bodies.palms)
    _shade_bodies(frame, bodies, owner, scene.lighting)
    if exposure is not None:
        if np.shape(exposure.joints_world)[1] != len(hands):
            raise InputError(f'exposure: joints of {np.shape(exposure.joints_world)[1]} hands '
                             f'for {len(hands)} hands')
        _expose(frame, bodies, owner, hands, exposure)
    depth = np.full(frame.inv_depth.shape, np.inf, np.float32)
    np.divide(1.0, frame.inv_depth, out=depth, where=frame.inv_depth > 0)
    return RenderOutput(degrade(frame.rgb, options), depth, _hand_masks(bodies, owner))
