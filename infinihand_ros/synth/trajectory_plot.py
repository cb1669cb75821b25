"""Top-view plot (PNG) of a sequence's camera path and wrist paths, drawn with OpenCV.

The view looks down the scene's gravity axis (x right, y up on the page), with a 0.5 m grid, the
table outline, the camera path with its viewing direction every second, and each wrist's path.
"""

from typing import Final

import cv2
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np

CANVAS_PX: Final = 720
MARGIN_PX: Final = 60
GRID_M: Final = 0.5
#: BGR colours for OpenCV drawing.
CAMERA_BGR: Final = (200, 90, 20)
WRIST_BGR: Final = {LEFT: (40, 160, 40), RIGHT: (40, 40, 210)}
TABLE_BGR: Final = (120, 120, 120)
GRID_BGR: Final = (225, 225, 225)
TEXT_BGR: Final = (30, 30, 30)
ARROW_M: Final = 0.15
FONT: Final = cv2.FONT_HERSHEY_SIMPLEX


def _table_corners(sequence: SyntheticSequence) -> np.ndarray:
    """Table top outline (4, 2) in the scene's x-y plane."""
    table = sequence.scene.table
    half = table.half_extents[:2]
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    cos, sin = np.cos(table.yaw_rad), np.sin(table.yaw_rad)
    return corners @ np.array([[cos, sin], [-sin, cos]]) + table.center[:2]


def plot_top_view(sequence: SyntheticSequence) -> np.ndarray:
    """Return an RGB uint8 image of the camera and wrist trajectories seen from above."""
    cameras = sequence.T_scene_cams[:, :2, 3]
    wrists = {t.side: j[:, 0, :2] for t, j in zip(sequence.tracks, sequence.joints_scene)}
    table = _table_corners(sequence)
    points = np.concatenate([cameras, table, *wrists.values()])
    low, high = points.min(axis=0) - 0.2, points.max(axis=0) + 0.2
    scale = (CANVAS_PX - 2 * MARGIN_PX) / float(np.max(high - low))

    def to_px(xy: np.ndarray) -> np.ndarray:
        px = (xy - low) * scale + MARGIN_PX
        return np.stack([px[..., 0], CANVAS_PX - px[..., 1]], axis=-1).round().astype(np.int32)

    canvas = np.full((CANVAS_PX, CANVAS_PX, 3), 255, np.uint8)
    for x in np.arange(np.ceil(low[0] / GRID_M), np.floor(high[0] / GRID_M) + 1) * GRID_M:
        a, b = to_px(np.array([[x, low[1]], [x, high[1]]]))
        cv2.line(canvas, tuple(map(int, a)), tuple(map(int, b)), GRID_BGR, 1)
    for y in np.arange(np.ceil(low[1] / GRID_M), np.floor(high[1] / GRID_M) + 1) * GRID_M:
        a, b = to_px(np.array([[low[0], y], [high[0], y]]))
        cv2.line(canvas, tuple(map(int, a)), tuple(map(int, b)), GRID_BGR, 1)
    cv2.polylines(canvas, [to_px(table)], True, TABLE_BGR, 2)
    cv2.polylines(canvas, [to_px(cameras)], False, CAMERA_BGR, 2, cv2.LINE_AA)
    step = max(1, int(round(sequence.config.fps)))
    for pose in sequence.T_scene_cams[::step]:
        forward = pose[:2, 2] / max(np.linalg.norm(pose[:2, 2]), 1e-6)
        a, b = to_px(np.stack([pose[:2, 3], pose[:2, 3] + ARROW_M * forward]))
        cv2.arrowedLine(canvas, tuple(map(int, a)), tuple(map(int, b)), CAMERA_BGR, 1,
                        cv2.LINE_AA, tipLength=0.3)
    for side, path in wrists.items():
        cv2.polylines(canvas, [to_px(path)], False, WRIST_BGR[side], 2, cv2.LINE_AA)
        cv2.circle(canvas, tuple(map(int, to_px(path[0]))), 5, WRIST_BGR[side], -1)
    cv2.circle(canvas, tuple(map(int, to_px(cameras[0]))), 6, CAMERA_BGR, -1)
    legend = [('camera (arrows: view, 1/s)', CAMERA_BGR), ('table', TABLE_BGR)] + [
        (f'{SIDE_NAMES[side]} wrist', WRIST_BGR[side]) for side in wrists]
    for row, (text, colour) in enumerate(legend):
        y = 24 + 22 * row
        cv2.line(canvas, (14, y - 5), (40, y - 5), colour, 3)
        cv2.putText(canvas, text, (48, y), FONT, 0.5, TEXT_BGR, 1, cv2.LINE_AA)
    caption = (f'top view, scene frame (x right, y up), grid {GRID_M} m; dots = start; '
               f'{len(cameras)} frames at {sequence.config.fps:g} FPS')
    cv2.putText(canvas, caption, (14, CANVAS_PX - 16), FONT, 0.42, TEXT_BGR, 1, cv2.LINE_AA)
    return canvas[:, :, ::-1].copy()
