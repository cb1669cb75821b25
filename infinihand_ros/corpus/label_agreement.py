"""Agreement of a 2D keypoint source with exact labels (the issue's pseudo-label figure).

For every visible true hand the source's best detection of the same side is compared with the
true 2D joints: the mean joint pixel error divided by the true box's longer side. Frames where
the source finds no hand of that side count as misses; a detection found only under the other
side's label counts as a side swap (MediaPipe's handedness is a classifier and can be wrong).
"""

from collections.abc import Sequence
from dataclasses import dataclass

from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.engine.hands.keypoints import Detection2D
import numpy as np


@dataclass(frozen=True)
class Agreement:
    """Normalised 2D errors of a source against exact labels.

    Attributes:
        errors: per matched hand-frame, mean joint error / box extent.
        hand_frames: visible true hand-frames.
        missed: hand-frames without any detection of that side.
        swapped: missed hand-frames whose hand was found under the other side's label.

    """

    errors: np.ndarray
    hand_frames: int
    missed: int
    swapped: int

    def summary(self) -> dict:
        """Return JSON-ready figures (median, mean and 90th percentile of the errors)."""
        stats = {name: float(fn(self.errors)) if len(self.errors) else None for name, fn in
                 (('median', np.median), ('mean', np.mean),
                  ('p90', lambda e: np.percentile(e, 90)))}
        return {'hand_frames': self.hand_frames, 'matched': len(self.errors),
                'missed': self.missed, 'side_swapped': self.swapped, **stats}


def _error(detection: Detection2D, truth: np.ndarray, box: np.ndarray) -> float:
    extent = max(box[2] - box[0], box[3] - box[1])
    return float(np.linalg.norm(np.asarray(detection.joints_2d) - truth, axis=1).mean() / extent)


def label_agreement(detections: Sequence[Sequence[Detection2D]], joints_2d: np.ndarray,
                    box_xyxy: np.ndarray, visible: np.ndarray) -> Agreement:
    """Compare per-frame detections with true (T, 2, 21, 2) joints, (T, 2, 4) boxes, (T, 2)."""
    errors, hand_frames, missed, swapped = [], 0, 0, 0
    for index, found in enumerate(detections):
        for side in SIDES:
            if not visible[index, side]:
                continue
            hand_frames += 1
            same = [d for d in found if d.side == side]
            if not same:
                missed += 1
                other = [d for d in found if d.side != side]
                swapped += any(_error(d, joints_2d[index, side], box_xyxy[index, side]) < 0.2
                               for d in other)
                continue
            best = max(same, key=lambda d: d.confidence)
            errors.append(_error(best, joints_2d[index, side], box_xyxy[index, side]))
    return Agreement(np.asarray(errors), hand_frames, missed, swapped)
