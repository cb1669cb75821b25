"""Procedural surface textures for the synthetic scenes (numpy noise and OpenCV primitives).

A texture is an RGB uint8 image (H, W, 3). It mixes multi-octave value noise between two random
colours, one optional large pattern (stripes, tiles or wood grain), random marks (blobs, lines,
text-like glyphs, dots) and a fine grain, so that every patch has corners for feature tracking.
Everything is drawn from the ``numpy.random.Generator`` passed in, so a seed fixes the texture.
"""

from typing import Final

import cv2
from infinihand_ros.core.errors import InputError
import numpy as np

#: Random colours: smallest and (by default) largest HSV saturation and range of HSV value
#: (brightness), in [0, 1]; indoor surfaces are mostly muted.
MIN_SATURATION: Final = 0.05
MAX_SATURATION: Final = 0.4
VALUE_RANGE: Final = (0.35, 0.92)
#: Smallest texture side in pixels.
MIN_TEXTURE_PX: Final = 8
#: Cell sizes (px) of the value-noise octaves and their weights (coarse to fine).
NOISE_CELLS_PX: Final = (96, 32, 10, 3)
NOISE_WEIGHTS: Final = (0.45, 0.3, 0.17, 0.08)
#: Per-pixel grain amplitude (uint8 units), so close-ups still have texture.
GRAIN_AMPLITUDE: Final = 10.0
#: Marks per square pixel of texture (blobs, lines, glyphs, dots).
MARK_DENSITY_PER_PX2: Final = 1.0 / 2500.0
#: Upper bound of marks per texture (bounds the generation time of big surfaces).
MAX_MARKS: Final = 400
#: Glyph set of the text-like marks.
GLYPHS: Final = 'ABCDEFGHKLMNPRSTUVWXYZ0123456789#%&@'
#: Probabilities of the large patterns: none, stripes, tiles, wood grain.
PATTERN_PROBS: Final = (0.25, 0.3, 0.2, 0.25)
#: Strength (0-1) of a large pattern blended over the noise.
PATTERN_STRENGTH_RANGE: Final = (0.25, 0.6)
#: Period range (px) of stripes and tiles.
PATTERN_PERIOD_RANGE_PX: Final = (12.0, 64.0)
#: Marks are this much darker or lighter than a palette colour at most (uint8 units).
MARK_CONTRAST: Final = 90.0
#: Size range of marks (ellipse radius, glyph height, ...) in texture pixels.
MARK_SIZE_RANGE_PX: Final = (2, 20)
#: ``cv2.putText`` font scale per pixel of glyph size.
GLYPH_SCALE_PER_PX: Final = 0.05
#: Chance that a texture gets a third, unrelated accent colour for its marks.
ACCENT_PROBABILITY: Final = 0.5


def random_colour(rng: np.random.Generator,
                  saturation_max: float = MAX_SATURATION) -> np.ndarray:
    """Draw a random RGB colour (3,) float in [0, 255], not too dark and not fully saturated.

    Args:
        rng: random generator.
        saturation_max: largest HSV saturation in [0, 1].

    """
    # Float HSV in OpenCV: hue in degrees [0, 360), saturation and value in [0, 1].
    hsv = np.array([[[rng.uniform(0.0, 360.0), rng.uniform(MIN_SATURATION, saturation_max),
                      rng.uniform(*VALUE_RANGE)]]], dtype=np.float32)
    return 255.0 * cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[0, 0].astype(np.float64)


def value_noise(rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    """Multi-octave value noise (H, W) float32 with zero mean and values roughly in [-1, 1].

    Args:
        rng: random generator.
        height: rows in pixels.
        width: columns in pixels.

    """
    out = np.zeros((height, width), np.float32)
    for cell, weight in zip(NOISE_CELLS_PX, NOISE_WEIGHTS):
        # Two extra grid cells so that the cubic upsampling covers the whole image.
        grid = rng.uniform(-1.0, 1.0, (height // cell + 2, width // cell + 2)).astype(np.float32)
        out += weight * cv2.resize(grid, (width, height), interpolation=cv2.INTER_CUBIC)
    return out


def _pattern(rng: np.random.Generator, height: int, width: int) -> np.ndarray | None:
    """Return a large pattern (H, W) float32 in [-1, 1], or None for no pattern."""
    kind = rng.choice(len(PATTERN_PROBS), p=PATTERN_PROBS)
    if kind == 0:
        return None
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    period = rng.uniform(*PATTERN_PERIOD_RANGE_PX)
    angle = rng.uniform(0.0, np.pi)
    along = xs * np.cos(angle) + ys * np.sin(angle)
    if kind == 1:
        return np.sign(np.sin(along * (2.0 * np.pi / period))).astype(np.float32)
    if kind == 2:
        across = -xs * np.sin(angle) + ys * np.cos(angle)
        cells = np.floor(along / period) + np.floor(across / period)
        return (np.mod(cells, 2.0) * 2.0 - 1.0).astype(np.float32)
    warp = value_noise(rng, height, width) * period * 2.0
    return np.sin((along + warp) * (2.0 * np.pi / period)).astype(np.float32)


def _mark_colour(rng: np.random.Generator, palette: np.ndarray) -> tuple[int, int, int]:
    """Pick a palette colour made darker or lighter (uint8 RGB tuple)."""
    colour = palette[rng.integers(0, len(palette))] + rng.uniform(-MARK_CONTRAST, MARK_CONTRAST)
    return tuple(int(c) for c in np.clip(colour, 0, 255))


def _draw_marks(rng: np.random.Generator, image: np.ndarray, palette: np.ndarray) -> None:
    """Draw random blobs, lines, glyphs and dots in palette colours into ``image`` (in place)."""
    height, width = image.shape[:2]
    count = min(MAX_MARKS, int(height * width * MARK_DENSITY_PER_PX2) + 2)
    size_hi = max(MARK_SIZE_RANGE_PX[0] + 1, min(MARK_SIZE_RANGE_PX[1], min(height, width) // 2))
    for _ in range(count):
        colour = _mark_colour(rng, palette)
        centre = (int(rng.integers(0, width)), int(rng.integers(0, height)))
        size = int(rng.integers(MARK_SIZE_RANGE_PX[0], size_hi))
        kind = rng.integers(0, 4)
        if kind == 0:
            axes = (size, int(rng.integers(1, size + 1)))
            cv2.ellipse(image, centre, axes, rng.uniform(0, 180), 0, 360, colour, -1, cv2.LINE_AA)
        elif kind == 1:
            end = (centre[0] + int(rng.integers(-3 * size, 3 * size + 1)),
                   centre[1] + int(rng.integers(-3 * size, 3 * size + 1)))
            cv2.line(image, centre, end, colour, int(rng.integers(1, 3)), cv2.LINE_AA)
        elif kind == 2:
            text = ''.join(rng.choice(list(GLYPHS), int(rng.integers(1, 6))))
            cv2.putText(image, text, centre, cv2.FONT_HERSHEY_SIMPLEX, size * GLYPH_SCALE_PER_PX,
                        colour, 1 + int(size > MARK_SIZE_RANGE_PX[1] // 2), cv2.LINE_AA)
        else:
            cv2.circle(image, centre, max(1, size // 4), colour, -1, cv2.LINE_AA)


def make_texture(rng: np.random.Generator, height: int, width: int,
                 colours: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Generate one procedural texture.

    Args:
        rng: random generator (the only source of randomness).
        height: rows in pixels (>= ``MIN_TEXTURE_PX``).
        width: columns in pixels (>= ``MIN_TEXTURE_PX``).
        colours: two RGB colours (3,) in [0, 255] to mix; random when None.

    Returns:
        RGB uint8 image (height, width, 3).

    Raises:
        InputError: if a side is smaller than ``MIN_TEXTURE_PX``.

    """
    if height < MIN_TEXTURE_PX or width < MIN_TEXTURE_PX:
        raise InputError(f'texture size must be at least {MIN_TEXTURE_PX} px per side, '
                         f'got {width}x{height}; pass a larger surface or resolution')
    if colours is None:
        colours = (random_colour(rng), random_colour(rng))
    first, second = (np.asarray(c, np.float32) for c in colours)
    mix = value_noise(rng, height, width)
    pattern = _pattern(rng, height, width)
    if pattern is not None:
        strength = rng.uniform(*PATTERN_STRENGTH_RANGE)
        mix = (1.0 - strength) * mix + strength * pattern
    weight = np.clip(0.5 + 0.5 * mix, 0.0, 1.0)[..., None]
    image = first * (1.0 - weight) + second * weight
    image += rng.uniform(-GRAIN_AMPLITUDE, GRAIN_AMPLITUDE, (height, width, 1)).astype(np.float32)
    texture = np.clip(image, 0, 255).astype(np.uint8)
    palette = [first, second]
    if rng.uniform() < ACCENT_PROBABILITY:
        palette.append(random_colour(rng).astype(np.float32))
    _draw_marks(rng, texture, np.array(palette))
    return texture


def shade_texture(texture: np.ndarray, shade: np.ndarray) -> np.ndarray:
    """Multiply a texture (H, W, 3) uint8 by a shading map resized to its size.

    Args:
        texture: RGB uint8 image.
        shade: (h, w) or (h, w, 3) float32 factors (1 = unchanged), any resolution; it is
            resized bilinearly to the texture.

    Returns:
        The shaded RGB uint8 image (H, W, 3).

    """
    height, width = texture.shape[:2]
    factors = cv2.resize(np.asarray(shade, np.float32), (width, height),
                         interpolation=cv2.INTER_LINEAR)
    if factors.ndim == 2:
        factors = factors[..., None]
    return np.clip(texture.astype(np.float32) * factors, 0, 255).astype(np.uint8)
