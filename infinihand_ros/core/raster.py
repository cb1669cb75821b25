"""Raster conventions shared by the synthetic renderer and the annotation masks.

Pixel (column i, row j) shows image point (u, v) = (i, j) (OpenCV). Polygons and lines are given
to OpenCV in fixed point with ``SUBPIXEL_BITS`` fraction bits, so the renderer's masks and the
masks drawn from annotations cover the same pixels.
"""

from typing import Final

import numpy as np

#: Fixed-point fraction bits of coordinates given to OpenCV drawing (polygons, blur line).
SUBPIXEL_BITS: Final = 4


def mask_box(mask: np.ndarray) -> np.ndarray:
    """Tight box (x0, y0, x1, y1) of a boolean mask, exclusive ends; zeros for an empty mask."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return np.zeros(4)
    return np.array([cols[0], rows[0], cols[-1] + 1, rows[-1] + 1], dtype=np.float64)
