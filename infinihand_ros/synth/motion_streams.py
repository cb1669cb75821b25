"""Real frames made hard for a hand source: fast turns, motion blur, hands hidden for a while.

- ``motion_blur``: a straight-line blur (a camera turning during the exposure).
- ``blurred_run``: a clip with some consecutive frames blurred.
- ``hands_hidden``: a clip with the hands' regions filled in from their surroundings on some
  frames (the hands lost, then back).
- ``shaken_crops``: a crop video of a photo around its hand, still at first, then turning fast
  to and fro (0.3 of the view per frame, blurred along the motion).
- ``panned_away``: a crop video of a photo that turns away from the hand (out of view for some
  frames) and back.
"""

from collections.abc import Sequence

import cv2
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.engine.hands.boxes import landmark_box
from infinihand_ros.synth.photo_streams import crop_stream
from infinihand_ros.synth.photo_streams import CropFrame
import numpy as np


def motion_blur(rgb: np.ndarray, length_px: int, angle_deg: float = 0.0) -> np.ndarray:
    """Return ``rgb`` blurred along a line ``length_px`` long at ``angle_deg`` (0: across)."""
    if length_px < 2:
        return rgb.copy()
    kernel = np.zeros((length_px, length_px), np.float32)
    kernel[length_px // 2, :] = 1.0
    centre = ((length_px - 1) / 2.0, (length_px - 1) / 2.0)
    kernel = cv2.warpAffine(kernel, cv2.getRotationMatrix2D(centre, angle_deg, 1.0),
                            (length_px, length_px))
    return cv2.filter2D(rgb, -1, kernel / kernel.sum(), borderType=cv2.BORDER_REFLECT)


def blurred_run(frames: Sequence[np.ndarray], start: int, count: int, length_px: int,
                angle_deg: float = 0.0) -> list[np.ndarray]:
    """Return ``frames`` with frames ``start`` .. ``start + count - 1`` motion-blurred."""
    return [motion_blur(frame, length_px, angle_deg) if start <= index < start + count
            else frame for index, frame in enumerate(frames)]


def hands_hidden(frames: Sequence[np.ndarray], landmarks: Sequence[Sequence[np.ndarray]],
                 start: int, count: int, margin: float = 0.3) -> list[np.ndarray]:
    """Return ``frames`` with the hands of frames ``start`` .. ``start + count - 1`` removed.

    Args:
        frames: RGB uint8 images.
        landmarks: per frame the hands' landmarks, each (21, 2) px (e.g. MediaPipe alone's).
        start: the first frame without hands.
        count: how many frames.
        margin: each hand's landmark box grows by this share of its size per side before it is
            filled in from its surroundings (OpenCV's inpainting).

    """
    hidden = []
    for index, (frame, hands) in enumerate(zip(frames, landmarks)):
        if not start <= index < start + count or not len(hands):
            hidden.append(frame)
            continue
        mask = np.zeros(frame.shape[:2], np.uint8)
        for joints in hands:
            x0, y0, x1, y1 = landmark_box(np.asarray(joints))
            grow = margin * max(x1 - x0, y1 - y0)
            cv2.rectangle(mask, (int(x0 - grow), int(y0 - grow)),
                          (int(x1 + grow), int(y1 + grow)), 255, -1)
        hidden.append(cv2.inpaint(frame, mask, 5, cv2.INPAINT_TELEA))
    return hidden


def _crops(rgb: np.ndarray, intrinsics: Intrinsics, hand: np.ndarray, offsets: np.ndarray
           ) -> list[CropFrame]:
    """Return crops three hand sizes wide, their centres at ``offsets`` (crop widths) from it."""
    centre = hand.mean(axis=0)
    width = float(np.clip(3.0 * np.ptp(hand, axis=0).max(), 160.0, rgb.shape[1]))
    centres = centre + np.stack([offsets * width, np.zeros_like(offsets)], axis=1)
    return crop_stream(rgb, intrinsics, centres, np.full(len(offsets), width))


def _blurred_along(frames: list[CropFrame], offsets: np.ndarray, blur: float
                   ) -> list[CropFrame]:
    """Blur each crop along its motion since the last, ``blur`` of the shift long."""
    shifts = np.abs(np.diff(offsets, prepend=offsets[0])) * frames[0].rgb.shape[1]
    return [CropFrame(motion_blur(frame.rgb, int(blur * shift)), frame.timestamp_ns,
                      frame.intrinsics) for frame, shift in zip(frames, shifts)]


def shaken_crops(rgb: np.ndarray, intrinsics: Intrinsics, hand: np.ndarray, still: int = 4,
                 shakes: int = 12, step: float = 0.3, blur: float = 0.25) -> list[CropFrame]:
    """Return a crop video around a photo's hand: ``still`` frames, then fast turns to and fro.

    The crop turns by ``step`` of its width per frame (left, back, right, back, ...), each
    frame blurred along the motion over ``blur`` of the shift (the exposure's share of the
    frame time); the hand (``hand``: its landmarks in the photo, px) stays in view. The
    intrinsics are exact (``crop_stream``).
    """
    pattern = np.array([0.0, step, 0.0, -step])
    offsets = np.concatenate([np.zeros(still), np.resize(np.roll(pattern, -1), shakes)])
    return _blurred_along(_crops(rgb, intrinsics, hand, offsets), offsets, blur)


def panned_away(rgb: np.ndarray, intrinsics: Intrinsics, hand: np.ndarray, still: int = 4,
                away: int = 4, after: int = 8, blur: float = 0.25) -> list[CropFrame]:
    """Return a crop video that turns away from a photo's hand for ``away`` frames and back.

    Still on the hand for ``still`` frames, then ``away`` (at least 3) frames turned away from
    it: a fast turn (0.4 of the view per frame, blurred as in ``shaken_crops``) to a view
    without the hand, held, and half of the turn back; then ``after`` still frames: the hand is
    back in full on frame ``still + away``.
    """
    side = 1.0 if hand.mean(axis=0)[0] < rgb.shape[1] / 2 else -1.0  # away from the near edge
    turn = np.concatenate([[0.4], np.full(away - 2, 0.8), [0.4]])
    offsets = np.concatenate([np.zeros(still), side * turn, np.zeros(after)])
    return _blurred_along(_crops(rgb, intrinsics, hand, offsets), offsets, blur)
