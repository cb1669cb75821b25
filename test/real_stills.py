"""Real pixels for tests: the shared hand photos, and crop "videos" with exact cameras.

``../shared/data/real_hands_stills`` (30 real hand photos, 640x480, fx = fy = 500) is read
from outside the repository; tests that use it skip when it is absent (``require_stills``).
``crop_stream`` turns one photo into a video: a crop window moving and zooming across it,
each crop resized to a fixed output size. Cropping and resizing change only the intrinsics
(the camera centre and orientation stay those of the photo), so every frame's exact
intrinsics are known, and a hand's position in the camera frame is the same in every frame.
"""

from dataclasses import dataclass
from pathlib import Path

import cv2
from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.core.datatypes import Intrinsics
import numpy as np
import pytest

STILLS = Path(__file__).resolve().parents[2] / 'shared' / 'data' / 'real_hands_stills'


def require_stills() -> list:
    """Return the stills' camera frames, or skip the test when the shared data is absent."""
    if not STILLS.is_dir():
        pytest.skip(f'real hand stills not found at {STILLS} (shared data absent)')
    return list(read_camera_frames(STILLS))


@dataclass(frozen=True)
class CropFrame:
    """One frame of a crop video: RGB uint8, its stamp and its exact intrinsics."""

    rgb: np.ndarray
    timestamp_ns: int
    intrinsics: Intrinsics


def crop_stream(rgb: np.ndarray, intrinsics: Intrinsics, centres: np.ndarray,
                widths: np.ndarray, size: tuple[int, int] = (320, 240),
                fps: float = 10.0) -> list[CropFrame]:
    """Return crops of ``rgb`` centred at ``centres`` (N, 2) px, ``widths`` (N,) px wide.

    Each crop has the output's aspect ratio, lies inside the photo and is resized to ``size``
    (width, height); its intrinsics follow exactly (shift by the crop corner, scale by the
    resize).
    """
    out_w, out_h = size
    frames = []
    for index, ((cx, cy), width) in enumerate(zip(centres, widths)):
        height = width * out_h / out_w
        x0 = float(np.clip(cx - width / 2, 0, rgb.shape[1] - width))
        y0 = float(np.clip(cy - height / 2, 0, rgb.shape[0] - height))
        scale = out_w / width
        # Pixel centres: source x maps to (x - x0 + 0.5) * scale - 0.5 in the crop.
        matrix = np.array([[scale, 0.0, (0.5 - x0) * scale - 0.5],
                           [0.0, scale, (0.5 - y0) * scale - 0.5]])
        crop = cv2.warpAffine(rgb, matrix, (out_w, out_h), flags=cv2.INTER_AREA)
        crop_k = Intrinsics(intrinsics.fx * scale, intrinsics.fy * scale,
                            (intrinsics.cx + 0.5 - x0) * scale - 0.5,
                            (intrinsics.cy + 0.5 - y0) * scale - 0.5, out_w, out_h)
        frames.append(CropFrame(crop, int(index * 1e9 / fps), crop_k))
    return frames
