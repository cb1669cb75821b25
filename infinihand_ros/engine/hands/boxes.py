"""Hand boxes: from landmarks, and their overlap."""

import numpy as np


def landmark_box(joints_2d: np.ndarray) -> np.ndarray:
    """Return the (x0, y0, x1, y1) box of (21, 2) landmarks."""
    return np.concatenate([joints_2d.min(axis=0), joints_2d.max(axis=0)])


def box_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Return the intersection over union of two (x0, y0, x1, y1) boxes (0 for empty ones)."""
    width = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    height = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = width * height
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return float(inter / union) if union > 0 else 0.0
