"""Per-hand masks and tight boxes rendered from hand annotations (paper Sec. 3.1).

The built-in hand's surface is the synthetic generator's: a palm slab and round cones around the
skeleton (``mano/capsules.py``) with the generator's joint radii, intersected with each pixel's
ray and z-tested between the two hands, so corpus masks match the generator's wherever no scene
object covers the hand. Real MANO meshes are filled triangle by triangle, far to near.
"""

from typing import Final

import cv2
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.raster import mask_box
from infinihand_ros.core.raster import SUBPIXEL_BITS
from infinihand_ros.mano import capsules as caps
import numpy as np

#: Near clipping plane of the generator's renderer (m).
NEAR_M: Final = 0.05


def _check_size(K: np.ndarray, width: int, height: int) -> np.ndarray:
    k = np.asarray(K, np.float64)
    if k.shape != (3, 3) or k[0, 0] <= 0 or k[1, 1] <= 0:
        raise InputError(f'K: expected a (3, 3) pinhole matrix with positive focal lengths, '
                         f'got {k.tolist()}')
    if width <= 0 or height <= 0:
        raise InputError(f'image size must be positive, got {width}x{height}')
    return k


def capsule_masks(joints_cam: np.ndarray, radii: np.ndarray, present: np.ndarray,
                  K: np.ndarray, width: int, height: int) -> np.ndarray:
    """Visible pixels of each hand's capsule surface.

    Args:
        joints_cam: (2, 21, 3) joints per side [left, right], camera frame, metres.
        radii: (2, 21) joint radii per side (m), e.g. ``mano.capsules.joint_radii(betas)``.
        present: (2,) bool, which sides to draw.
        K: (3, 3) intrinsics, pixels.
        width: image width (px).
        height: image height (px).

    Returns:
        (2, H, W) bool masks; a pixel belongs to the nearer hand.

    Raises:
        InputError: for a bad K or image size.

    """
    k = _check_size(K, width, height)
    hands = [(np.asarray(joints_cam[side], np.float64), np.asarray(radii[side], np.float64), side)
             for side in SIDES if present[side]]
    capsule_set = caps.build_capsule_set(hands)
    palms = caps.build_palm_set(hands)
    depth = np.full((height, width), np.inf)
    owner = np.full((height, width), -1, np.int8)
    ray_x = (np.arange(width) - k[0, 2]) / k[0, 0]
    ray_y = (np.arange(height) - k[1, 2]) / k[1, 1]
    for intersect, bodies, rects in (
            (caps.ray_capsule_depth, capsule_set,
             caps.capsule_rects(capsule_set, k, NEAR_M, width, height)),
            (caps.ray_palm_depth, palms, caps.palm_rects(palms, k, NEAR_M, width, height))):
        for index, (x0, y0, x1, y1) in enumerate(rects.tolist()):
            if x0 >= x1 or y0 >= y1:
                continue
            hit = intersect(ray_x[None, x0:x1], ray_y[y0:y1, None], bodies, index)
            with np.errstate(invalid='ignore'):
                nearer = (hit >= NEAR_M) & (hit < depth[y0:y1, x0:x1])
            depth[y0:y1, x0:x1][nearer] = hit[nearer]
            owner[y0:y1, x0:x1][nearer] = bodies.sides[index]
    return np.stack([owner == side for side in SIDES])


def mesh_masks(vertices_cam: np.ndarray, faces: np.ndarray, present: np.ndarray,
               K: np.ndarray, width: int, height: int) -> np.ndarray:
    """Visible pixels of each hand's triangle mesh (real MANO), painted far to near.

    Args:
        vertices_cam: (2, V, 3) vertices per side, camera frame, metres.
        faces: (F, 3) int vertex indices of the mesh.
        present: (2,) bool, which sides to draw.
        K: (3, 3) intrinsics, pixels.
        width: image width (px).
        height: image height (px).

    Returns:
        (2, H, W) bool masks.

    Raises:
        InputError: for a bad K or image size.

    """
    k = _check_size(K, width, height)
    labels = np.zeros((height, width), np.uint8)
    triangles, depths, sides = [], [], []
    for side in SIDES:
        if not present[side]:
            continue
        corners = np.asarray(vertices_cam[side], np.float64)[np.asarray(faces)]
        keep = np.all(corners[..., 2] > NEAR_M, axis=1)
        corners = corners[keep]
        pixels = corners[..., :2] / corners[..., 2:] * k[[0, 1], [0, 1]] + k[:2, 2]
        triangles.append(pixels)
        depths.append(corners[..., 2].mean(axis=1))
        sides.append(np.full(len(pixels), side + 1, np.uint8))
    if triangles:
        pixels, depth, label = (np.concatenate(part) for part in (triangles, depths, sides))
        # Pixel (i, j) shows image point (i, j) (the renderer's convention).
        points = np.round(pixels * (1 << SUBPIXEL_BITS)).astype(np.int32)
        for index in np.argsort(-depth):
            cv2.fillConvexPoly(labels, points[index], int(label[index]), cv2.LINE_8,
                               SUBPIXEL_BITS)
    return np.stack([labels == side + 1 for side in SIDES])


def masks_to_boxes(masks: np.ndarray) -> np.ndarray:
    """Tight boxes (2, 4) (x0, y0, x1, y1), exclusive ends, of (2, H, W) masks; zeros if empty."""
    return np.stack([mask_box(mask) for mask in masks])
