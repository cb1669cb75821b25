"""Tests of the raster helpers shared by the renderer and the annotation masks."""

from infinihand_ros.core.raster import mask_box
import numpy as np


def test_mask_box_is_tight_with_exclusive_ends() -> None:
    mask = np.zeros((10, 12), bool)
    mask[2:5, 3:9] = True
    np.testing.assert_array_equal(mask_box(mask), [3, 2, 9, 5])
    np.testing.assert_array_equal(mask_box(np.zeros((4, 4), bool)), [0, 0, 0, 0])
