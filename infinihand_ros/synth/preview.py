"""Preview drawings for people: 2D hand skeletons on images and labelled contact sheets."""

from collections.abc import Sequence
from typing import Final

import cv2
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import FINGER_JOINTS
from infinihand_ros.core.hand_conventions import JOINT_PARENTS
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import side_name
from infinihand_ros.core.validation import as_array
import numpy as np

#: RGB colour of each finger (thumb, index, middle, ring, pinky) and of the wrist.
FINGER_RGB: Final = ((230, 60, 60), (240, 200, 40), (60, 200, 80), (50, 150, 240), (190, 80, 220))
WRIST_RGB: Final = (255, 255, 255)
#: Tint blended into the finger colours per side (left, right) and its weight.
SIDE_TINT_RGB: Final = ((0, 255, 255), (255, 140, 0))
SIDE_TINT_WEIGHT: Final = 0.3
#: Line thickness and joint radius (pixels).
BONE_THICKNESS_PX: Final = 2
JOINT_RADIUS_PX: Final = 3
#: Contact sheet: label font scale, label bar height and gap colour.
LABEL_FONT_SCALE: Final = 0.45
LABEL_BAR_PX: Final = 18
SHEET_BACKGROUND_RGB: Final = (32, 32, 32)


def _joint_colours(side: int) -> list[tuple[int, int, int]]:
    """RGB colour of each of the 21 joints (its finger's colour, tinted by the side)."""
    tint = np.array(SIDE_TINT_RGB[side], np.float64)
    colours = [WRIST_RGB] * NUM_JOINTS
    for finger, joints in enumerate(FINGER_JOINTS):
        mixed = (1.0 - SIDE_TINT_WEIGHT) * np.array(FINGER_RGB[finger]) + SIDE_TINT_WEIGHT * tint
        for joint in joints:
            colours[joint] = tuple(int(c) for c in mixed)
    return colours


def draw_skeleton(rgb: np.ndarray, joints_2d: np.ndarray, side: int) -> np.ndarray:
    """Draw a 21-joint hand skeleton (OpenPose order) on a copy of an RGB image.

    Args:
        rgb: (H, W, 3) uint8 image.
        joints_2d: (21, 2) pixel coordinates (u, v); non-finite joints are skipped.
        side: 0 left, 1 right (tints the finger colours and labels the wrist 'L' or 'R').

    Returns:
        A new (H, W, 3) uint8 image with bones as lines and joints as dots.

    Raises:
        InputError: on a wrong image or joint array shape.
        ValueError: on a side other than 0 or 1.

    """
    image = np.array(as_array(rgb, 'rgb', (None, None, 3), dtype=np.uint8))
    joints = as_array(joints_2d, 'joints_2d', (NUM_JOINTS, 2), finite=False)
    label = side_name(side)[0].upper()
    colours = _joint_colours(side)
    valid = np.all(np.isfinite(joints), axis=1) & np.all(np.abs(joints) < 1e6, axis=1)
    points = [tuple(int(round(c)) for c in joint) if ok else None
              for joint, ok in zip(joints, valid)]
    for child, parent in enumerate(JOINT_PARENTS):
        if parent >= 0 and points[child] and points[parent]:
            cv2.line(image, points[parent], points[child], colours[child], BONE_THICKNESS_PX,
                     cv2.LINE_AA)
    for point, colour in zip(points, colours):
        if point:
            cv2.circle(image, point, JOINT_RADIUS_PX, colour, -1, cv2.LINE_AA)
    if points[0]:
        cv2.putText(image, label, (points[0][0] + 4, points[0][1] - 4), cv2.FONT_HERSHEY_SIMPLEX,
                    LABEL_FONT_SCALE, WRIST_RGB, 1, cv2.LINE_AA)
    return image


def contact_sheet(images: Sequence[np.ndarray], cols: int,
                  labels: Sequence[str] | None = None) -> np.ndarray:
    """Tile RGB images in a grid, each with a small label bar above it.

    Args:
        images: (H, W, 3) uint8 images; smaller ones are padded to the largest size.
        cols: tiles per row (>= 1).
        labels: one text per image, or None for no text.

    Returns:
        (rows * (H + bar), cols * W, 3) uint8 sheet.

    Raises:
        InputError: on no images, a bad ``cols``, a label count that differs from the images,
            or a non-RGB image.

    """
    if len(images) == 0:
        raise InputError('contact_sheet: no images given; pass at least one frame')
    if cols < 1:
        raise InputError(f'contact_sheet: cols must be >= 1, got {cols}')
    if labels is not None and len(labels) != len(images):
        raise InputError(f'contact_sheet: {len(labels)} labels for {len(images)} images; '
                         'pass one label per image or None')
    tiles = [as_array(image, f'images[{i}]', (None, None, 3), dtype=np.uint8)
             for i, image in enumerate(images)]
    tile_h = max(t.shape[0] for t in tiles) + LABEL_BAR_PX
    tile_w = max(t.shape[1] for t in tiles)
    rows = -(-len(tiles) // cols)
    sheet = np.empty((rows * tile_h, cols * tile_w, 3), np.uint8)
    sheet[:] = SHEET_BACKGROUND_RGB
    for index, tile in enumerate(tiles):
        top, left = (index // cols) * tile_h, (index % cols) * tile_w
        sheet[top + LABEL_BAR_PX:top + LABEL_BAR_PX + tile.shape[0],
              left:left + tile.shape[1]] = tile
        if labels is not None:
            cv2.putText(sheet, str(labels[index]), (left + 4, top + LABEL_BAR_PX - 5),
                        cv2.FONT_HERSHEY_SIMPLEX, LABEL_FONT_SCALE, WRIST_RGB, 1, cv2.LINE_AA)
    return sheet
