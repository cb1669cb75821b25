"""Rendering through a distorting lens: a pinhole canvas that covers the view, then a warp.

The renderer draws pinhole images only. For a lens with distortion, ``LensWarp`` finds, for every
pixel of the distorted image, the pixel of the pinhole camera with the same K that sees the same
ray (``core.distortion.undistort_pixels``: OpenCV's inverse of the lens). The pinhole image is
drawn on a canvas grown (same focal lengths, principal point shifted) until it holds every such
pixel, up to ``MAX_CANVAS_SCALE`` times the image per side; ``warp_*`` then resample it into the
distorted image with ``cv2.remap`` (bilinear for colour, nearest for depth and labels).
"""

from dataclasses import dataclass
from typing import Final

import cv2
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.distortion import undistort_pixels
import numpy as np

#: Largest pinhole canvas side, in image sides (wide lenses lose what lies beyond, black).
MAX_CANVAS_SCALE: Final = 3.0
#: Pixels of margin around the farthest pinhole pixel (bilinear reads one more).
_MARGIN_PX: Final = 2
#: Canvas coordinate of pixels OpenCV could not undistort (read as the border: black).
_OUTSIDE_PX: Final = -1.0e4


@dataclass(frozen=True)
class LensWarp:
    """The pinhole canvas of a distorted view and the map from it to the distorted image.

    Attributes:
        canvas_K: (3, 3) K of the pinhole canvas (the lens's focal lengths, shifted centre).
        canvas_size: (width, height) of the canvas, pixels.
        map_x: (H, W) float32 canvas x read by each distorted pixel.
        map_y: (H, W) float32 canvas y read by each distorted pixel.

    """

    canvas_K: np.ndarray
    canvas_size: tuple[int, int]
    map_x: np.ndarray
    map_y: np.ndarray

    def warp_rgb(self, rgb: np.ndarray) -> np.ndarray:
        """Return the distorted (H, W, 3) uint8 image of a canvas image (bilinear)."""
        return cv2.remap(rgb, self.map_x, self.map_y, cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0))

    def warp_depth(self, depth: np.ndarray) -> np.ndarray:
        """Return the distorted (H, W) float32 depth of a canvas depth map (nearest, +inf out)."""
        return cv2.remap(depth, self.map_x, self.map_y, cv2.INTER_NEAREST,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=float('inf'))

    def warp_masks(self, masks: np.ndarray) -> np.ndarray:
        """Return distorted (N, H, W) bool masks of canvas masks (nearest)."""
        return np.stack([cv2.remap(mask.astype(np.uint8), self.map_x, self.map_y,
                                   cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                                   borderValue=0) > 0 for mask in masks])


def lens_warp(intrinsics: Intrinsics) -> LensWarp:
    """Return the canvas and map that render ``intrinsics``' distorted view (see the module)."""
    width, height = intrinsics.width, intrinsics.height
    K = intrinsics.matrix()
    ys, xs = np.mgrid[0:height, 0:width]
    pixels = np.column_stack([xs.ravel(), ys.ravel()]).astype(np.float64)
    pinhole = undistort_pixels(pixels, K, intrinsics.distortion_model, intrinsics.distortion)
    finite = np.isfinite(pinhole).all(axis=1)
    low = np.min(pinhole[finite], axis=0) if finite.any() else np.zeros(2)
    high = np.max(pinhole[finite], axis=0) if finite.any() else np.array([width - 1, height - 1])
    limit = (MAX_CANVAS_SCALE - 1.0) / 2.0 * np.array([width, height])
    before = np.clip(np.ceil(-low) + _MARGIN_PX, 0, limit).astype(int)
    after = np.clip(np.ceil(high - np.array([width - 1, height - 1])) + _MARGIN_PX, 0,
                    limit).astype(int)
    canvas_K = K.copy()
    canvas_K[0, 2] += before[0]
    canvas_K[1, 2] += before[1]
    canvas = pinhole + before
    canvas[~finite] = _OUTSIDE_PX
    size = (int(width + before[0] + after[0]), int(height + before[1] + after[1]))
    maps = canvas.reshape(height, width, 2).astype(np.float32)
    return LensWarp(canvas_K, size, np.ascontiguousarray(maps[..., 0]),
                    np.ascontiguousarray(maps[..., 1]))
