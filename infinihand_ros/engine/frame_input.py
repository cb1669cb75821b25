"""Checking incoming frames and fitting them to the model's input size.

Frames are letterboxed: scaled to fit (aspect kept), then padded symmetrically to the model size,
so the geometry stays exact (one scale factor, a shift of the principal point) and the image centre
stays the centre, as the model's FoV-only intrinsics assume.
"""

from dataclasses import dataclass

import cv2
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
import numpy as np


@dataclass(frozen=True)
class Letterbox:
    """Map between source pixels and model-input pixels: ``model = scale * source + offset``.

    The two scales differ only by the rounding of the resized size (fractions of a percent).
    """

    scale_x: float
    scale_y: float
    offset_x: float
    offset_y: float
    source_size: tuple[int, int]
    model_size: tuple[int, int]

    def intrinsics_to_model(self, intrinsics: Intrinsics) -> Intrinsics:
        """Return the intrinsics of the model-input image."""
        return Intrinsics(intrinsics.fx * self.scale_x, intrinsics.fy * self.scale_y,
                          intrinsics.cx * self.scale_x + self.offset_x,
                          intrinsics.cy * self.scale_y + self.offset_y, *self.model_size)

    def intrinsics_to_source(self, intrinsics: Intrinsics) -> Intrinsics:
        """Return the source-image intrinsics of model-input intrinsics."""
        return Intrinsics(intrinsics.fx / self.scale_x, intrinsics.fy / self.scale_y,
                          (intrinsics.cx - self.offset_x) / self.scale_x,
                          (intrinsics.cy - self.offset_y) / self.scale_y, *self.source_size)

    def map_to_source(self, values_model: np.ndarray) -> np.ndarray:
        """Crop the padding off a model-size (H, W) map and resize it to the source size."""
        width, height = self.source_size
        left = int(round(self.offset_x - 0.5 * self.scale_x + 0.5))
        top = int(round(self.offset_y - 0.5 * self.scale_y + 0.5))
        inner = values_model[top:top + int(round(height * self.scale_y)),
                             left:left + int(round(width * self.scale_x))]
        return cv2.resize(inner, (width, height), interpolation=cv2.INTER_LINEAR)

    def points_to_source(self, points_model: np.ndarray) -> np.ndarray:
        """Map (..., 2) model-input pixels to source pixels."""
        offset = np.array([self.offset_x, self.offset_y])
        scale = np.array([self.scale_x, self.scale_y])
        return (np.asarray(points_model, dtype=np.float64) - offset) / scale


def check_image(image: object, name: str = 'image') -> np.ndarray:
    """Return ``image`` if it is a non-empty (H, W, 3) uint8 RGB array.

    Raises:
        InputError: naming what is wrong and what to send instead.

    """
    if not isinstance(image, np.ndarray):
        raise InputError(f'{name}: expected a numpy array, got {type(image).__name__}')
    if image.ndim != 3 or image.shape[2] != 3:
        raise InputError(f'{name}: expected (H, W, 3) RGB, got shape {image.shape}; convert '
                         'mono or RGBA images to RGB first')
    if image.dtype != np.uint8:
        raise InputError(f'{name}: expected uint8 pixels, got {image.dtype}; scale to 0..255')
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise InputError(f'{name}: image is empty or degenerate ({image.shape[1]}x'
                         f'{image.shape[0]} px)')
    return image


def check_intrinsics(intrinsics: Intrinsics | None, image: np.ndarray) -> Intrinsics | None:
    """Return ``intrinsics`` if it matches the image size (None passes: the model predicts FoV).

    Raises:
        InputError: for a size mismatch (finiteness and positivity are checked by Intrinsics).

    """
    if intrinsics is None:
        return None
    height, width = image.shape[:2]
    if (intrinsics.width, intrinsics.height) != (width, height):
        raise InputError(f'intrinsics are for {intrinsics.width}x{intrinsics.height} px but the '
                         f'image is {width}x{height} px; send the matching CameraInfo')
    return intrinsics


def letterbox(image: np.ndarray, model_size: tuple[int, int]) -> tuple[np.ndarray, Letterbox]:
    """Fit an RGB image into ``model_size`` (width, height); return it and the pixel mapping."""
    height, width = image.shape[:2]
    model_width, model_height = model_size
    scale = min(model_width / width, model_height / height)
    new_width = max(1, min(model_width, int(round(width * scale))))
    new_height = max(1, min(model_height, int(round(height * scale))))
    interpolation = cv2.INTER_AREA if scale < 1.0 else cv2.INTER_LINEAR
    resized = cv2.resize(image, (new_width, new_height), interpolation=interpolation)
    left, top = (model_width - new_width) // 2, (model_height - new_height) // 2
    canvas = np.zeros((model_height, model_width, 3), dtype=np.uint8)
    canvas[top:top + new_height, left:left + new_width] = resized
    # Pixel centres: a source pixel x maps to (x + 0.5) * s' - 0.5 + left with s' = new / old.
    scale_x, scale_y = new_width / width, new_height / height
    mapping = Letterbox(scale_x=scale_x, scale_y=scale_y,
                        offset_x=left + 0.5 * scale_x - 0.5, offset_y=top + 0.5 * scale_y - 0.5,
                        source_size=(width, height), model_size=(model_width, model_height))
    return canvas, mapping
