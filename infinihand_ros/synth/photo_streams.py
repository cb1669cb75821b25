"""Videos with exactly known cameras made from one photo (real textures for tracking checks).

- ``crop_stream``: a crop window moving and zooming across the photo; cropping and resizing
  change only the intrinsics (the camera centre and orientation stay the photo's), so every
  frame's exact intrinsics are known and a hand's camera-frame position is the same in each.
- ``rotation_stream``: views from cameras turned about the photo's centre (exact pure rotation).
- ``pasted_stream``: a still camera with a patch (a hand and arm, ``hand_and_arm_patch``) moving
  across the photo (``wandering_corners``).
- ``as_webcam``: any of these with a webcam's sensor noise and JPEG compression, new every frame.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.hands.config import MEDIAPIPE
from infinihand_ros.engine.hands.mediapipe_detector import MediaPipeDetector
import numpy as np


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


def rotation_stream(rgb: np.ndarray, intrinsics: Intrinsics, rotations: np.ndarray,
                    out_intrinsics: Intrinsics, fps: float = 10.0) -> list[CropFrame]:
    """Return views of ``rgb`` from cameras turned by ``rotations`` (N, 3, 3) about its centre.

    A camera at the photo's centre turned by R (camera-to-world, the photo's camera is the
    world) sees the photo's pixel ``K_photo R K_out^-1 u`` at its pixel ``u``: every frame is
    an exact pure rotation (no parallax), with ``out_intrinsics``. Pixels outside the photo are
    black.
    """
    size = (out_intrinsics.width, out_intrinsics.height)
    frames = []
    for index, rotation in enumerate(rotations):
        homography = intrinsics.matrix() @ rotation @ np.linalg.inv(out_intrinsics.matrix())
        view = cv2.warpPerspective(rgb, homography, size,
                                   flags=cv2.WARP_INVERSE_MAP | cv2.INTER_AREA)
        frames.append(CropFrame(view, int(index * 1e9 / fps), out_intrinsics))
    return frames


def pasted_stream(background: np.ndarray, patch: np.ndarray, corners: np.ndarray,
                  intrinsics: Intrinsics, fps: float = 10.0) -> list[CropFrame]:
    """Return a still camera's frames: ``background`` with ``patch`` pasted at ``corners``.

    ``corners`` (N, 2) are the patch's top-left pixels (x, y), whole pixels inside the image:
    a hand (and arm) moving in front of a fixed camera, whose true pose is the identity.
    """
    frames = []
    height, width = patch.shape[:2]
    for index, (x0, y0) in enumerate(np.asarray(corners, dtype=int)):
        image = background.copy()
        image[y0:y0 + height, x0:x0 + width] = patch
        frames.append(CropFrame(image, int(index * 1e9 / fps), intrinsics))
    return frames


def as_webcam(frames: Sequence[CropFrame], noise_sigma: float = 2.0, jpeg_quality: int = 85,
              seed: int = 0) -> list[CropFrame]:
    """Return ``frames`` with fresh Gaussian sensor noise (sigma in 8-bit levels) and JPEG.

    A real still camera never delivers the same pixels twice; the cameras stay exact.
    """
    rng = np.random.default_rng(seed)
    out = []
    for frame in frames:
        noisy = frame.rgb + rng.normal(0.0, noise_sigma, frame.rgb.shape)
        encoded = cv2.imencode('.jpg', np.clip(noisy, 0, 255).astype(np.uint8)[..., ::-1],
                               [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])[1]
        rgb = cv2.imdecode(encoded, cv2.IMREAD_COLOR)[..., ::-1].copy()
        out.append(CropFrame(rgb, frame.timestamp_ns, frame.intrinsics))
    return out


def wandering_corners(image_hw: tuple[int, int], patch_hw: tuple[int, int], frames: int,
                      cycles: tuple[float, float] = (2.0, 3.0)) -> np.ndarray:
    """Return (frames, 2) top-left pixels (x, y) of a patch wandering over a whole image.

    x and y follow sines of ``cycles`` periods over the stream, spanning every position where
    the patch lies inside the image (``pasted_stream``'s corners).
    """
    steps = np.linspace(0.0, 1.0, frames)
    span_y, span_x = (image - patch - 1 for image, patch in zip(image_hw, patch_hw))
    return np.stack([span_x * (0.5 + 0.5 * np.sin(2 * np.pi * cycles[0] * steps)),
                     span_y * (0.5 + 0.5 * np.sin(2 * np.pi * cycles[1] * steps))], axis=1)


def hand_and_arm_patch(photos: Sequence[np.ndarray], margin_px: int = 20) -> np.ndarray | None:
    """Return a patch of the first RGB photo where MediaPipe finds a hand, grown down to its arm.

    The patch is the hand's landmark box grown by ``margin_px`` and by half its height downwards
    (where the arm is); None when no photo shows a hand.
    """
    detector = MediaPipeDetector(HandsConfig(source=MEDIAPIPE))
    try:
        for rgb in photos:
            detections = detector.detect(rgb, 0)
            detector.reset()
            if detections:
                joints = detections[0].joints_2d
                height, width = rgb.shape[:2]
                x0, y0 = np.maximum(np.floor(joints.min(axis=0)).astype(int) - margin_px, 0)
                x1, y1 = np.ceil(joints.max(axis=0)).astype(int) + margin_px
                return rgb[y0:min(y1 + (y1 - y0) // 2, height), x0:min(x1, width)]
    finally:
        detector.close()
    return None
