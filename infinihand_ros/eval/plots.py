"""PNG plots of one evaluated sequence: the top view of the trajectories and per-frame errors.

The top view shows the world's x-z plane (world = first camera: x right, z forward, seen from
above) with the camera and both wrists, ground truth thick and ours thin; the error plot shows
per frame our world joint error per side on the matched pairs (mm) and the distance between the
predicted and the true camera centre (mm, raw: no alignment).
"""

from pathlib import Path
from typing import Final

import cv2
from infinihand_ros.core.atomic_io import atomic_write_bytes
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.eval.runner import SequenceEvaluation
import numpy as np

CANVAS_PX: Final = 640
MARGIN_PX: Final = 40
CAMERA_BGR: Final = (200, 90, 20)
SIDE_BGR: Final = {0: (40, 160, 40), 1: (40, 40, 210)}
TEXT_BGR: Final = (30, 30, 30)
GRID_BGR: Final = (225, 225, 225)
FONT: Final = cv2.FONT_HERSHEY_SIMPLEX
#: World axes drawn in the top view: x (right) and z (forward).
TOP_AXES: Final = (0, 2)


def _legend(canvas: np.ndarray, entries: list[tuple[str, tuple[int, int, int], int]]) -> None:
    for row, (text, colour, thickness) in enumerate(entries):
        y = 22 + 20 * row
        cv2.line(canvas, (12, y - 5), (38, y - 5), colour, thickness)
        cv2.putText(canvas, text, (46, y), FONT, 0.45, TEXT_BGR, 1, cv2.LINE_AA)


def top_view(evaluation: SequenceEvaluation, truth_T: np.ndarray, truth_joints: np.ndarray,
             truth_visible: np.ndarray) -> np.ndarray:
    """Return a BGR image: camera and wrist paths from above, ground truth vs ours."""
    pred = evaluation.predictions
    paths = [(truth_T[:, :3, 3], CAMERA_BGR, 3), (pred.T_world_cam[:, :3, 3], CAMERA_BGR, 1)]
    for side in SIDES:
        paths.append((np.where(truth_visible[:, side, None], truth_joints[:, side, WRIST],
                               np.nan), SIDE_BGR[side], 3))
        paths.append((np.where(evaluation.matched[:, side, None],
                               pred.joints_world[:, side, WRIST], np.nan), SIDE_BGR[side], 1))
    points = np.concatenate([p[:, TOP_AXES] for p, _, _ in paths])
    points = points[np.isfinite(points).all(axis=1)]
    canvas = np.full((CANVAS_PX, CANVAS_PX, 3), 255, np.uint8)
    if len(points):
        low, high = points.min(axis=0) - 0.05, points.max(axis=0) + 0.05
        scale = (CANVAS_PX - 2 * MARGIN_PX) / float(max(np.max(high - low), 1e-3))

        def to_px(xz: np.ndarray) -> np.ndarray:
            px = (xz - low) * scale + MARGIN_PX
            return np.stack([px[:, 0], CANVAS_PX - px[:, 1]], axis=1).round().astype(np.int32)

        for path, colour, thickness in paths:
            xz = path[:, TOP_AXES]
            finite = np.isfinite(xz).all(axis=1)
            # Draw each run of consecutive finite points as its own polyline.
            breaks = np.flatnonzero(np.diff(finite.astype(int)) != 0) + 1
            for run in np.split(np.arange(len(xz)), breaks):
                if len(run) > 1 and finite[run[0]]:
                    cv2.polylines(canvas, [to_px(xz[run])], False, colour, thickness,
                                  cv2.LINE_AA)
    _legend(canvas, [('camera', CAMERA_BGR, 3)] + [(f'{SIDE_NAMES[s]} wrist', SIDE_BGR[s], 3)
                                                   for s in SIDES]
            + [('thick: ground truth, thin: ours', TEXT_BGR, 1)])
    cv2.putText(canvas, f'{evaluation.name}: top view (world x right, z forward), metres',
                (12, CANVAS_PX - 14), FONT, 0.45, TEXT_BGR, 1, cv2.LINE_AA)
    return canvas


def error_plot(evaluation: SequenceEvaluation, truth_T: np.ndarray,
               truth_joints: np.ndarray) -> np.ndarray:
    """Return a BGR image: per-frame world joint error per side (mm) and camera error (mm)."""
    pred = evaluation.predictions
    series = []
    for side in SIDES:
        error = np.linalg.norm(pred.joints_world[:, side] - truth_joints[:, side],
                               axis=-1).mean(axis=-1) * 1000.0
        series.append((f'{SIDE_NAMES[side]} hand W-MPJPE', np.where(
            evaluation.matched[:, side], error, np.nan), SIDE_BGR[side]))
    camera = np.linalg.norm(pred.T_world_cam[:, :3, 3] - truth_T[:, :3, 3], axis=-1) * 1000.0
    series.append(('camera position', camera, CAMERA_BGR))
    width, height = CANVAS_PX * 3 // 2, CANVAS_PX // 2
    canvas = np.full((height, width, 3), 255, np.uint8)
    values = np.concatenate([s for _, s, _ in series])
    top = float(np.nanmax(values)) if np.isfinite(values).any() else 1.0
    top = max(top, 1.0)
    frames = max(len(camera) - 1, 1)
    for fraction in (0.25, 0.5, 0.75, 1.0):
        y = int(height - MARGIN_PX - fraction * (height - 2 * MARGIN_PX))
        cv2.line(canvas, (MARGIN_PX, y), (width - 10, y), GRID_BGR, 1)
        cv2.putText(canvas, f'{fraction * top:.0f}', (2, y + 4), FONT, 0.35, TEXT_BGR, 1)
    for _, values_mm, colour in series:
        x = MARGIN_PX + np.arange(len(values_mm)) / frames * (width - MARGIN_PX - 10)
        y = height - MARGIN_PX - values_mm / top * (height - 2 * MARGIN_PX)
        for a in range(len(values_mm) - 1):
            if np.isfinite(y[a]) and np.isfinite(y[a + 1]):
                cv2.line(canvas, (int(x[a]), int(y[a])), (int(x[a + 1]), int(y[a + 1])),
                         colour, 1, cv2.LINE_AA)
    _legend(canvas, [(name, colour, 2) for name, _, colour in series])
    cv2.putText(canvas, f'{evaluation.name}: error (mm) per frame', (MARGIN_PX, height - 12),
                FONT, 0.45, TEXT_BGR, 1, cv2.LINE_AA)
    return canvas


def write_plots(directory: str | Path, evaluation: SequenceEvaluation, truth_T: np.ndarray,
                truth_joints: np.ndarray, truth_visible: np.ndarray) -> list[Path]:
    """Write ``<name>_top_view.png`` and ``<name>_errors.png`` (atomically); return the paths."""
    directory = Path(directory)
    images = {f'{evaluation.name}_top_view.png': top_view(evaluation, truth_T, truth_joints,
                                                          truth_visible),
              f'{evaluation.name}_errors.png': error_plot(evaluation, truth_T, truth_joints)}
    paths = []
    for name, image in images.items():
        ok, data = cv2.imencode('.png', image)
        if not ok:
            raise OSError(f'PNG encoding of {name} failed')
        atomic_write_bytes(directory / name, data.tobytes())
        paths.append(directory / name)
    return paths
