"""Where detection fails: recall per side and per target size, and why each target was missed.

Ours (the paper reports FAcc, Recall and F1 only). Built on the appendix-A matching
(``eval.matching``), so its counts add up to the pooled detection metrics: every missed target
(an on-screen target left unmatched, a false negative) gets exactly one cause, checked in this
order:

- ``side_swapped``: a kept prediction of the *other* side overlaps the target as a match would
  (IoU with the enlarged target box above 0.1): the hand was found, under the wrong side;
- ``mislocated``: a kept prediction of the target's side exists in the frame but does not match it
  (it lies elsewhere, or another target of that side took it);
- ``undetected``: no kept prediction of the target's side in the frame.

Target size is the square root of the target box's area over the image width, so the bins mean
the same at every resolution.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.eval.matching import box_iou
from infinihand_ros.eval.matching import enlarge_boxes
from infinihand_ros.eval.matching import EvalFrame
from infinihand_ros.eval.matching import FrameMatch
from infinihand_ros.eval.matching import IOU_THRESHOLD
import numpy as np

#: Why a target was missed, in the order the causes are checked.
MISS_CAUSES: Final = ('side_swapped', 'mislocated', 'undetected')
#: Upper edges of the size bins: sqrt(target box area) / image width.
SIZE_BIN_EDGES: Final = (0.1, 0.2, 0.4)


@dataclass(frozen=True)
class RecallCount:
    """Targets and matched targets of one group (recall NaN when the group is empty)."""

    targets: int
    matched: int

    @property
    def recall(self) -> float:
        """Return matched / targets."""
        return self.matched / self.targets if self.targets else float('nan')


@dataclass(frozen=True)
class DetectionBreakdown:
    """Detection counts split by side, target size and miss cause (on-screen targets only).

    Attributes:
        by_side: one count per side (0 left, 1 right).
        by_size: one count per size bin (``size_bins`` labels).
        misses: missed targets per cause (``MISS_CAUSES``); they sum to the false negatives.

    """

    by_side: tuple[RecallCount, ...]
    by_size: tuple[RecallCount, ...]
    misses: dict[str, int]

    @staticmethod
    def size_bins() -> tuple[str, ...]:
        """Return the size bins' labels (``< 0.1 W``, ..., ``>= 0.4 W``)."""
        edges = SIZE_BIN_EDGES
        return ((f'< {edges[0]:g} W',)
                + tuple(f'{low:g}-{high:g} W' for low, high in zip(edges, edges[1:]))
                + (f'>= {edges[-1]:g} W',))

    def as_dict(self) -> dict[str, object]:
        """Return a JSON-ready dict (recall null for an empty group)."""
        def group(count: RecallCount) -> dict[str, object]:
            recall = count.recall
            return {'targets': count.targets,
                    'recall': recall if np.isfinite(recall) else None}
        return {'by_side': {name: group(count)
                            for name, count in zip(SIDE_NAMES, self.by_side)},
                'by_size': {label: group(count)
                            for label, count in zip(self.size_bins(), self.by_size)},
                'misses': dict(self.misses)}


def miss_cause(frame: EvalFrame, target: int) -> str:
    """Return why ``frame.targets[target]``, a missed target of the frame, was missed."""
    side = frame.targets[target].side
    kept = [p for p in frame.predictions if p.is_positive]
    others = [p.box for p in kept if p.side != side]
    if others:
        iou = box_iou(enlarge_boxes(frame.targets[target].box[None]), np.stack(others))
        if (iou > IOU_THRESHOLD).any():
            return 'side_swapped'
    if any(p.side == side for p in kept):
        return 'mislocated'
    return 'undetected'


def _size_bin(box: np.ndarray, width: int) -> int:
    size = np.sqrt((box[2] - box[0]) * (box[3] - box[1])) / width
    return int(np.searchsorted(SIZE_BIN_EDGES, size, side='right'))


def detection_breakdown(frames: Sequence[EvalFrame],
                        matches: Sequence[FrameMatch]) -> DetectionBreakdown:
    """Split the matched frames' on-screen targets by side, size and miss cause.

    Raises:
        InputError: when ``matches`` does not hold one ``FrameMatch`` per frame.

    """
    if len(matches) != len(frames):
        raise InputError(f'matches: expected one FrameMatch per frame ({len(frames)}), '
                         f'got {len(matches)}')
    side_counts = np.zeros((len(SIDES), 2), int)  # targets, matched
    size_counts = np.zeros((len(SIZE_BIN_EDGES) + 1, 2), int)
    misses = dict.fromkeys(MISS_CAUSES, 0)
    for frame, match in zip(frames, matches):
        outcomes = [(t, True) for t, _ in match.matched] + [(t, False) for t in match.missed]
        for target, found in outcomes:
            hand = frame.targets[target]
            for counts, row in ((side_counts, hand.side),
                                (size_counts, _size_bin(hand.box, frame.width))):
                counts[row] += (1, int(found))
            if not found:
                misses[miss_cause(frame, target)] += 1
    return DetectionBreakdown(
        by_side=tuple(RecallCount(int(n), int(m)) for n, m in side_counts),
        by_size=tuple(RecallCount(int(n), int(m)) for n, m in size_counts), misses=misses)
