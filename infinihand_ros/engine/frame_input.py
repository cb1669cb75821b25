"""Checking incoming frames and fitting them to the model input, with the exact pixel mapping.

``fit_image(image, mode, config)`` implements the three ``GeometryConfig.preprocessing`` modes
(``model_size_for`` gives the input size each one produces for a source size):

- ``letterbox`` (ours): scaled to fit ``image_width`` x ``image_height`` (aspect kept, OpenCV
  area / linear resampling), padded symmetrically with black.
- ``resize_crop`` (LingBot-Map / VGGT ``load_and_preprocess_images`` ``mode="crop"``, the
  upstream default): width set to ``image_width``, height ``round(h * W / w / patch) * patch``
  (Python rounding, as upstream), bicubic; a taller result is centre-cropped to ``image_width``
  rows (top offset ``(new_h - W) // 2``). 640x480 -> 518x392, 1920x1080 -> 518x294.
- ``resize_pad`` (upstream ``mode="pad"``): the longer side set to ``image_width``, the other
  rounded to the patch as above, bicubic, padded white (255) to ``image_width`` squared
  (left/top pad = half the padding, rounded down).

Bicubic is torch's antialiased bicubic on uint8 (PIL's kernel, a = -0.5, with PIL's antialiasing
when shrinking); upstream resizes with PIL, and the two differ by at most 2/255 on under 1% of
pixels (measured with Pillow 13 on 640x480, 1920x1080, 480x640 and 300x200 frames).

Every mode is one scale and one shift per axis (pixel centres at integers, as OpenCV and
``grid_sample(align_corners=False)``): ``model = scale * source + offset``. ``FrameMapping``
carries it both ways for points, intrinsics and dense maps; pixels a crop cut away come back as
NaN (or the ``fill`` asked for) when a model-size map is mapped to the source.

Lens distortion is taken out before anything else looks at a frame: ``LensRectifier`` renders a
frame whose intrinsics carry a distortion model as the pinhole camera with the same K and size
(``cv2.remap``, bilinear, maps cached per lens and size), so the model, the tracker and the hand
detector all see a pinhole image in which K projects a point where the lens put it in the
original frame. Pixels the lens never saw are black.
"""

from collections import OrderedDict
from dataclasses import dataclass
import threading

import cv2
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.distortion import rectification_maps
from infinihand_ros.core.errors import InputError
from infinihand_ros.model.config import AggregatorConfig
from infinihand_ros.model.config import LETTERBOX
from infinihand_ros.model.config import PREPROCESSING_MODES
from infinihand_ros.model.config import RESIZE_CROP
from infinihand_ros.model.config import RESIZE_PAD
import numpy as np
import torch

#: Pad value of ``resize_pad`` (upstream pads with 1.0 = white) and of ``letterbox`` (black).
PAD_WHITE = 255
PAD_BLACK = 0


@dataclass(frozen=True)
class FrameMapping:
    """Map between source pixels and model-input pixels: ``model = scale * source + offset``.

    Attributes:
        scale_x: model pixels per source pixel along x.
        scale_y: along y (differs from ``scale_x`` by the rounding of the resized size).
        offset_x: model x of source pixel centre x = 0.
        offset_y: model y of source pixel centre y = 0.
        source_size: (width, height) of the source image, pixels.
        model_size: (width, height) of the model input, pixels.
        content_box: (x0, y0, x1, y1) model pixels that hold source content (x1, y1 exclusive);
            the rest is padding.

    """

    scale_x: float
    scale_y: float
    offset_x: float
    offset_y: float
    source_size: tuple[int, int]
    model_size: tuple[int, int]
    content_box: tuple[int, int, int, int]

    def intrinsics_to_model(self, intrinsics: Intrinsics) -> Intrinsics:
        """Return the intrinsics of the model-input image (the lens distortion is kept)."""
        return intrinsics.with_matrix(intrinsics.fx * self.scale_x, intrinsics.fy * self.scale_y,
                                      intrinsics.cx * self.scale_x + self.offset_x,
                                      intrinsics.cy * self.scale_y + self.offset_y,
                                      *self.model_size)

    def intrinsics_to_source(self, intrinsics: Intrinsics) -> Intrinsics:
        """Return the source-image intrinsics of model-input intrinsics (distortion kept)."""
        return intrinsics.with_matrix(intrinsics.fx / self.scale_x, intrinsics.fy / self.scale_y,
                                      (intrinsics.cx - self.offset_x) / self.scale_x,
                                      (intrinsics.cy - self.offset_y) / self.scale_y,
                                      *self.source_size)

    def points_to_source(self, points_model: np.ndarray) -> np.ndarray:
        """Map (..., 2) model-input pixels (x, y) to source pixels, float64."""
        offset = np.array([self.offset_x, self.offset_y])
        scale = np.array([self.scale_x, self.scale_y])
        return (np.asarray(points_model, dtype=np.float64) - offset) / scale

    def points_to_model(self, points_source: np.ndarray) -> np.ndarray:
        """Map (..., 2) source pixels (x, y) to model-input pixels, float64."""
        offset = np.array([self.offset_x, self.offset_y])
        scale = np.array([self.scale_x, self.scale_y])
        return np.asarray(points_source, dtype=np.float64) * scale + offset

    def map_to_source(self, values_model: np.ndarray, fill: float = float('nan')
                      ) -> np.ndarray:
        """Resample a model-size map (H, W) or (H, W, C) at every source pixel centre.

        Bilinear inside the content box (padding is never read; the half pixel along its rim
        repeats the edge); source pixels whose centre lies outside it, i.e. that a crop cut
        away, get ``fill``. Float64 maps stay float64, anything else comes back float32.

        Raises:
            InputError: when the map is not of the model size.

        """
        values = np.asarray(values_model)
        width, height = self.model_size
        if values.shape[:2] != (height, width):
            raise InputError(f'map_to_source: expected a ({height}, {width}, ...) model-size '
                             f'map, got shape {values.shape}')
        dtype = np.float64 if values.dtype == np.float64 else np.float32
        x0, y0, x1, y1 = self.content_box
        content = values[y0:y1, x0:x1].astype(dtype, copy=False)
        source_width, source_height = self.source_size
        v = np.arange(source_height) * self.scale_y + self.offset_y - y0
        u = np.arange(source_width) * self.scale_x + self.offset_x - x0
        trailing = (1,) * (values.ndim - 2)
        low, high, frac = _linear_taps(v, y1 - y0)
        frac = frac.astype(dtype).reshape(-1, 1, *trailing)
        rows = content[low] * (1 - frac) + content[high] * frac
        low, high, frac = _linear_taps(u, x1 - x0)
        frac = frac.astype(dtype).reshape(1, -1, *trailing)
        out = rows[:, low] * (1 - frac) + rows[:, high] * frac
        out[(v < -0.5) | (v > y1 - y0 - 0.5)] = fill
        out[:, (u < -0.5) | (u > x1 - x0 - 0.5)] = fill
        return out


def _linear_taps(coords: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (lower index, upper index, weight of the upper) of linear interpolation."""
    clipped = np.clip(coords, 0.0, size - 1)
    low = np.minimum(np.floor(clipped).astype(np.intp), max(size - 2, 0))
    return low, np.minimum(low + 1, size - 1), clipped - low


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


class LensRectifier:
    """Renders distorted frames as pinhole images with the same K; thread-safe.

    The remap tables of the ``capacity`` lenses used last are kept (keyed by the intrinsics,
    which hold the image size).
    """

    def __init__(self, capacity: int = 4) -> None:
        """Start with no table; keep at most ``capacity`` of them."""
        self._capacity = capacity
        self._maps: OrderedDict[Intrinsics, tuple[np.ndarray, np.ndarray]] = OrderedDict()
        self._last: Intrinsics | None = None
        self._lock = threading.Lock()

    def rectify(self, image: np.ndarray, intrinsics: Intrinsics | None) -> np.ndarray:
        """Return the (H, W, 3) uint8 image the pinhole camera with ``intrinsics``' K sees.

        An image without intrinsics, or with a pinhole lens, comes back as it is (no copy).

        Raises:
            InputError: for a bad image or intrinsics of another size (``check_image``,
                ``check_intrinsics``).

        """
        if intrinsics is None or not intrinsics.is_distorted:
            with self._lock:
                self._last = None
            return image
        check_intrinsics(intrinsics, check_image(image))
        with self._lock:
            maps = self._maps.get(intrinsics)
            if maps is None:
                maps = rectification_maps(intrinsics.matrix(), intrinsics.distortion_model,
                                          intrinsics.distortion,
                                          (intrinsics.width, intrinsics.height))
                self._maps[intrinsics] = maps
                while len(self._maps) > self._capacity:
                    self._maps.popitem(last=False)
            else:
                self._maps.move_to_end(intrinsics)
            self._last = intrinsics
        return cv2.remap(image, maps[0], maps[1], cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0))

    def rectify_like_last(self, image: np.ndarray) -> np.ndarray:
        """Rectify an image whose intrinsics are not known yet with the last frame's lens.

        For reading an image ahead of its CameraInfo: a stream keeps its lens. The image comes
        back as it is when the last frame was pinhole or of another size.
        """
        with self._lock:
            last = self._last
        if last is None or image.shape[:2] != (last.height, last.width):
            return image
        return self.rectify(image, last)


def _check_mode(mode: str) -> None:
    """Raise InputError for an unknown preprocessing mode."""
    if mode not in PREPROCESSING_MODES:
        raise InputError(f'preprocessing mode must be one of {list(PREPROCESSING_MODES)}, '
                         f'got {mode!r}')


def _resized_size(source_w: int, source_h: int, mode: str, config: AggregatorConfig
                  ) -> tuple[int, int]:
    """Return the (width, height) a ``resize_*`` mode scales the source to, before crop / pad.

    Raises:
        InputError: when the shorter side rounds to less than one patch.

    """
    target, patch = config.image_width, config.patch_size
    if mode == RESIZE_PAD and source_h > source_w:
        size = (round(source_w * (target / source_h) / patch) * patch, target)
    else:
        size = (target, round(source_h * (target / source_w) / patch) * patch)
    if min(size) < patch:
        raise InputError(f'a {source_w}x{source_h} px frame resized to width {target} is '
                         f'{size[0]}x{size[1]} px, less than one {patch}-px patch; crop it '
                         'to a less extreme aspect ratio first')
    return size


def model_size_for(source_w: int, source_h: int, mode: str, config: AggregatorConfig
                   ) -> tuple[int, int]:
    """Return the model input (width, height) ``fit_image`` makes of a source size.

    Args:
        source_w: source width in pixels.
        source_h: source height in pixels.
        mode: ``GeometryConfig.preprocessing``.
        config: the aggregator config (``image_width``, ``image_height``, ``patch_size``).

    Returns:
        ``letterbox``: the configured size; ``resize_crop``: (``image_width``, the rounded
        height, at most ``image_width``); ``resize_pad``: (``image_width``, ``image_width``).
        Both sides are multiples of the patch.

    Raises:
        InputError: for an unknown mode or a frame too elongated for one patch row.

    """
    _check_mode(mode)
    if mode == LETTERBOX:
        return config.image_width, config.image_height
    width, height = _resized_size(source_w, source_h, mode, config)
    if mode == RESIZE_PAD:
        return config.image_width, config.image_width
    return width, min(height, config.image_width)


def _resize_bicubic(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Resize uint8 RGB (H, W, 3) to ``size`` (width, height): antialiased bicubic (a = -0.5)."""
    pixels = torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1)[None]
    resized = torch.nn.functional.interpolate(pixels, size=(size[1], size[0]), mode='bicubic',
                                              antialias=True, align_corners=False)
    return resized[0].permute(1, 2, 0).numpy()


def _mapping(source: tuple[int, int], resized: tuple[int, int], shift: tuple[int, int],
             model: tuple[int, int]) -> FrameMapping:
    """Return the mapping of a resize to ``resized`` placed at ``shift`` in a ``model`` canvas."""
    scale_x, scale_y = resized[0] / source[0], resized[1] / source[1]
    # Pixel centres: source x maps to (x + 0.5) * scale - 0.5 + shift.
    x0, y0 = max(shift[0], 0), max(shift[1], 0)
    x1 = min(shift[0] + resized[0], model[0])
    y1 = min(shift[1] + resized[1], model[1])
    return FrameMapping(scale_x=scale_x, scale_y=scale_y, offset_x=shift[0] + 0.5 * scale_x - 0.5,
                        offset_y=shift[1] + 0.5 * scale_y - 0.5, source_size=source,
                        model_size=model, content_box=(x0, y0, x1, y1))


def letterbox(image: np.ndarray, model_size: tuple[int, int]
              ) -> tuple[np.ndarray, FrameMapping]:
    """Fit an RGB image into ``model_size`` (width, height); return it and the pixel mapping."""
    height, width = image.shape[:2]
    model_width, model_height = model_size
    scale = min(model_width / width, model_height / height)
    new_width = max(1, min(model_width, int(round(width * scale))))
    new_height = max(1, min(model_height, int(round(height * scale))))
    interpolation = cv2.INTER_AREA if scale < 1.0 else cv2.INTER_LINEAR
    resized = cv2.resize(image, (new_width, new_height), interpolation=interpolation)
    left, top = (model_width - new_width) // 2, (model_height - new_height) // 2
    canvas = np.full((model_height, model_width, 3), PAD_BLACK, dtype=np.uint8)
    canvas[top:top + new_height, left:left + new_width] = resized
    return canvas, _mapping((width, height), (new_width, new_height), (left, top),
                            (model_width, model_height))


def fit_image(image: np.ndarray, mode: str, config: AggregatorConfig
              ) -> tuple[np.ndarray, FrameMapping]:
    """Fit a checked RGB frame to the model input of ``mode`` (see the module docstring).

    Args:
        image: (H, W, 3) uint8 RGB (see ``check_image``).
        mode: ``GeometryConfig.preprocessing``.
        config: the aggregator config (input width, letterbox height, patch size).

    Returns:
        The (h, w, 3) uint8 model input, (w, h) = ``model_size_for(W, H, mode, config)``, and
        the mapping between its pixels and the source's.

    Raises:
        InputError: for an unknown mode or a frame too elongated for one patch row.

    """
    _check_mode(mode)
    height, width = image.shape[:2]
    model = model_size_for(width, height, mode, config)
    if mode == LETTERBOX:
        return letterbox(image, model)
    resized_size = _resized_size(width, height, mode, config)
    resized = _resize_bicubic(image, resized_size)
    if mode == RESIZE_CROP:
        top = (resized_size[1] - model[1]) // 2
        return (np.ascontiguousarray(resized[top:top + model[1]]),
                _mapping((width, height), resized_size, (0, -top), model))
    left, top = (model[0] - resized_size[0]) // 2, (model[1] - resized_size[1]) // 2
    canvas = np.full((model[1], model[0], 3), PAD_WHITE, dtype=np.uint8)
    canvas[top:top + resized_size[1], left:left + resized_size[0]] = resized
    return canvas, _mapping((width, height), resized_size, (left, top), model)
