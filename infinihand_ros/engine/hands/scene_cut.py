"""Cuts between scenes in an image stream, told apart from fast turns and motion blur.

Two consecutive images are a cut when their hue-saturation histograms (of 160 px wide
thumbnails) differ by more than ``hands.scene_cut_distance`` (Bhattacharyya distance), and
still do once the views are made comparable: the second thumbnail shifted onto the first (phase
correlation of their grey levels; a camera turning fast shifts the view by up to a third of it
per frame) and both smoothed alike (a blurred frame's colours are mixed along the motion), the
histograms of their overlap differ by as much. Unrelated photos in a row stay cuts; a fast turn
or a blurred frame of the same scene is not one.
"""

from typing import Final

import cv2
import numpy as np

#: Histogram bins (hue, saturation) and the thumbnail width the test uses.
CUT_BINS: Final = (16, 16)
CUT_THUMBNAIL_PX: Final = 160
#: The thumbnails are smoothed by a Gaussian this share of their width (sigma) for the second test.
SMOOTHING: Final = 0.025
#: The views are compared after the shift only where they still overlap by this share each way.
MIN_OVERLAP: Final = 0.5


def thumbnail(image: np.ndarray) -> np.ndarray:
    """Return an RGB uint8 image at most ``CUT_THUMBNAIL_PX`` wide."""
    height, width = image.shape[:2]
    if width <= CUT_THUMBNAIL_PX:
        return image
    size = (CUT_THUMBNAIL_PX, max(1, round(height * CUT_THUMBNAIL_PX / width)))
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA)


def colour_histogram(image: np.ndarray) -> np.ndarray:
    """Return the normalised hue-saturation histogram of an RGB uint8 image."""
    hsv = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2HSV)
    histogram = cv2.calcHist([hsv], [0, 1], None, list(CUT_BINS), [0, 180, 0, 256])
    return cv2.normalize(histogram, histogram).ravel()


def histogram_distance(first: np.ndarray, second: np.ndarray) -> float:
    """Return the Bhattacharyya distance of two histograms (0 alike .. 1 disjoint)."""
    return float(cv2.compareHist(first, second, cv2.HISTCMP_BHATTACHARYYA))


def aligned_distance(first: np.ndarray, second: np.ndarray) -> float:
    """Return the histogram distance of two thumbnails' overlap, ``second`` shifted onto ``first``.

    Both are smoothed alike first (``SMOOTHING``). 1.0 where the shift leaves less than
    ``MIN_OVERLAP`` of the view each way, or the sizes differ.
    """
    if first.shape != second.shape:
        return 1.0
    grey = [cv2.cvtColor(view, cv2.COLOR_RGB2GRAY).astype(np.float32) for view in (first, second)]
    height, width = grey[0].shape
    window = cv2.createHanningWindow((width, height), cv2.CV_32F)
    (dx, dy), _ = cv2.phaseCorrelate(grey[0], grey[1], window)
    shift_x, shift_y = round(dx), round(dy)  # second(x + shift) shows first(x)
    if (width - abs(shift_x) < MIN_OVERLAP * width
            or height - abs(shift_y) < MIN_OVERLAP * height):
        return 1.0
    sigma = SMOOTHING * width
    first, second = (cv2.GaussianBlur(view, (0, 0), sigma) for view in (first, second))
    x0, y0 = max(0, -shift_x), max(0, -shift_y)
    x1, y1 = min(width, width - shift_x), min(height, height - shift_y)
    return histogram_distance(
        colour_histogram(first[y0:y1, x0:x1]),
        colour_histogram(second[y0 + shift_y:y1 + shift_y, x0 + shift_x:x1 + shift_x]))


class SceneCuts:
    """Tells, image by image, whether an image starts a new scene (``reset`` between streams)."""

    def __init__(self, distance: float) -> None:
        """Compare images at this histogram distance (``hands.scene_cut_distance``)."""
        self.distance = distance
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # thumbnail, histogram

    def is_cut(self, image: np.ndarray) -> bool:
        """Return whether RGB uint8 ``image`` starts a new scene after the last image."""
        small = thumbnail(image)
        histogram = colour_histogram(small)
        last, self._last = self._last, (small, histogram)
        return (last is not None
                and histogram_distance(last[1], histogram) > self.distance
                and aligned_distance(last[0], small) > self.distance)

    def reset(self) -> None:
        """Forget the last image (a new stream)."""
        self._last = None
