"""Which hand is which: MediaPipe's label, the arm's side of entry, and each hand's history.

A hand's side is decided from its log-odds of being a right hand (positive: right):

- MediaPipe's handedness label and score ``p``: ``+-log(p / (1 - p))`` (0 where it is unsure);
- on a head-mounted view (``hands.egocentric``), the arm's side of entry: the wearer's right
  forearm comes into the image from the lower right, the left one from the lower left. The
  forearm is taken along the wrist's direction away from the middle knuckle; where that ray
  leaves the image tells the side: through the right or left border fully, through the bottom
  border by how far from the centre it leaves, through the top border not at all (not the
  wearer's arm). Its full weight is ``ARM_WEIGHT``, MediaPipe's label at a score of 0.9, so
  it decides where MediaPipe is less sure and never against a surer label;
- the hand's history (``SideTracker``): each hand is followed from frame to frame by its wrist,
  and its side is that of its decayed sum of per-frame log-odds, so one unsure frame does not
  flip a hand whose side was clear, and a hand whose first label was wrong turns once the
  evidence says so.

Two hands of one frame take different sides (the one more likely right is right), except one
hand seen twice (``is_duplicate``), whose weaker copy is dropped.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from dataclasses import field
import math
from typing import Final

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import MIDDLE_MCP
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.engine.hands.boxes import box_iou
from infinihand_ros.engine.hands.boxes import landmark_box
from infinihand_ros.engine.hands.keypoints import Detection2D
import numpy as np

#: Log-odds of the arm's side of entry at full strength: MediaPipe's label at a score of 0.9.
ARM_WEIGHT: Final = math.log(0.9 / 0.1)
#: A forearm leaving through the bottom border this share of the half width off the centre
#: gives full arm evidence (less: proportionally less).
BOTTOM_FULL_OFFSET: Final = 0.5
#: MediaPipe's scores are clipped to [0.5, this] before the log-odds (a score of 1 is not
#: infinitely sure).
MAX_LABEL_SCORE: Final = 0.995
#: A followed hand's log-odds are multiplied by this per frame (memory of a few frames) and
#: kept within +- ``LOG_ODDS_CAP`` (so steady contrary evidence turns it within a few frames).
DECAY_PER_FRAME: Final = 0.8
LOG_ODDS_CAP: Final = 8.0
#: A hand continues a followed hand whose wrist was within this share of the image diagonal.
MATCH_RADIUS: Final = 0.25
#: A followed hand unseen for more frames is forgotten.
MAX_GAP_FRAMES: Final = 15
#: Two same-sided hands overlapping more than this (IoU), or with wrists closer than
#: ``DUPLICATE_WRIST_FRACTION`` of the hand's box size, are one hand seen twice.
DUPLICATE_IOU: Final = 0.5
DUPLICATE_WRIST_FRACTION: Final = 0.25
OTHER_SIDE: Final = {LEFT: RIGHT, RIGHT: LEFT}


def label_log_odds(side: int, score: float) -> float:
    """Return the log-odds of a right hand from a classifier's ``side`` label and its score."""
    p = min(max(score, 0.5), MAX_LABEL_SCORE)
    odds = math.log(p / (1.0 - p))
    return odds if side == RIGHT else -odds


def arm_entry(joints_2d: np.ndarray, width: int, height: int) -> float:
    """Return where the forearm enters the image, as evidence of a right hand in [-1, 1].

    Args:
        joints_2d: (21, 2) pixels, OpenPose order.
        width, height: the image's size, pixels.

    Returns:
        +1 the right border (a head-mounted view's right arm), -1 the left border, through the
        bottom border by the crossing's offset from the centre, 0 through the top border or
        for a degenerate hand (no evidence).

    """
    size = np.array([width, height], dtype=np.float64)
    direction = np.asarray(joints_2d[WRIST] - joints_2d[MIDDLE_MCP], dtype=np.float64)
    if not np.all(np.isfinite(direction)) or np.hypot(*direction) < 1e-6:
        return 0.0
    start = np.clip(np.asarray(joints_2d[WRIST], dtype=np.float64), 0.0, size)
    with np.errstate(divide='ignore'):  # an axis the ray does not move along: never crossed
        reach = np.where(direction > 0, (size - start) / direction,
                         np.where(direction < 0, -start / direction, np.inf))
    if reach[0] < reach[1]:  # the left or right border
        return 1.0 if direction[0] > 0 else -1.0
    if direction[1] < 0:  # the top border
        return 0.0
    crossing = start[0] + reach[1] * direction[0]
    offset = (2.0 * crossing / width - 1.0) / BOTTOM_FULL_OFFSET
    return float(np.clip(offset, -1.0, 1.0))


def is_duplicate(a: Detection2D, b: Detection2D) -> bool:
    """Return whether two detections are one hand (boxes overlap, or wrists nearly coincide)."""
    box_a, box_b = landmark_box(a.joints_2d), landmark_box(b.joints_2d)
    size = max(np.ptp(a.joints_2d, axis=0).max(), np.ptp(b.joints_2d, axis=0).max(), 1.0)
    wrists = float(np.linalg.norm(a.joints_2d[WRIST] - b.joints_2d[WRIST]))
    return box_iou(box_a, box_b) > DUPLICATE_IOU or wrists < DUPLICATE_WRIST_FRACTION * size


@dataclass
class _Followed:
    """A hand followed from frame to frame: its wrist, its evidence, when it was last seen."""

    wrist_px: np.ndarray
    log_odds: float
    frame: int


@dataclass(frozen=True)
class SideDecision:
    """One frame's hands with their sides (``SideTracker.decide``).

    Attributes:
        hands: the kept hands, ``side`` as decided, the most confident first.
        indices: their indices in the frame's hands.
        duplicates: hands dropped as a more confident hand seen twice (or beyond two hands).
        relabelled: kept hands whose side differs from the source's label.

    """

    hands: tuple[Detection2D, ...] = ()
    indices: tuple[int, ...] = ()
    duplicates: int = 0
    relabelled: int = 0


@dataclass
class SideTracker:
    """Decides each hand's side over a stream (see the module docstring); frames in order.

    Attributes:
        egocentric: the camera is head-mounted: the arm's side of entry counts.
        mirrored: the images are mirrored (a selfie view): the arm's evidence is swapped.

    """

    egocentric: bool
    mirrored: bool = False
    _followed: list[_Followed] = field(default_factory=list)
    _frame: int = -1

    def reset(self) -> None:
        """Forget the followed hands (a new stream or scene)."""
        self._followed.clear()

    def evidence(self, hand: Detection2D, width: int, height: int) -> float:
        """Return one frame's log-odds that ``hand`` is a right hand (label and arm)."""
        odds = label_log_odds(hand.side, hand.confidence)
        if self.egocentric:
            arm = arm_entry(hand.joints_2d, width, height)
            odds += ARM_WEIGHT * (-arm if self.mirrored else arm)
        return odds

    def decide(self, hands: Sequence[Detection2D], width: int, height: int) -> SideDecision:
        """Return the next frame's hands with their sides, at most one per side."""
        self._frame += 1
        self._followed = [f for f in self._followed
                          if self._frame - f.frame <= MAX_GAP_FRAMES]
        matched = self._match(hands, MATCH_RADIUS * math.hypot(width, height))
        odds = []
        for hand, followed in zip(hands, matched):
            now = self.evidence(hand, width, height)
            if followed is not None:
                now += followed.log_odds * DECAY_PER_FRAME ** (self._frame - followed.frame)
            odds.append(float(np.clip(now, -LOG_ODDS_CAP, LOG_ODDS_CAP)))
        decision = _one_per_side(hands, odds)
        for k in decision.indices:
            wrist = np.asarray(hands[k].joints_2d[WRIST], dtype=np.float64)
            if matched[k] is None:
                self._followed.append(_Followed(wrist, odds[k], self._frame))
            else:
                matched[k].wrist_px, matched[k].log_odds = wrist, odds[k]
                matched[k].frame = self._frame
        return decision

    def _match(self, hands: Sequence[Detection2D], radius: float) -> list[_Followed | None]:
        """Return per hand the followed hand it continues (nearest wrists first), or None."""
        pairs = sorted((float(np.linalg.norm(f.wrist_px - hand.joints_2d[WRIST])), k, j)
                       for k, hand in enumerate(hands) for j, f in enumerate(self._followed))
        matched: list[_Followed | None] = [None] * len(hands)
        taken = set()
        for distance, k, j in pairs:
            if distance <= radius and matched[k] is None and j not in taken:
                matched[k] = self._followed[j]
                taken.add(j)
        return matched


def _one_per_side(hands: Sequence[Detection2D], odds: Sequence[float]) -> SideDecision:
    """Return the hands with sides from their log-odds: of two, the more likely right is right.

    The most confident hand comes first; a hand that repeats a kept hand of the same side
    (``is_duplicate``), or one beyond two, is dropped.
    """
    def side_of(k: int) -> int:
        return RIGHT if odds[k] > 0 else LEFT if odds[k] < 0 else hands[k].side

    kept: list[int] = []
    for k in sorted(range(len(hands)), key=lambda k: -hands[k].confidence):
        if len(kept) < 2 and not any(side_of(j) == side_of(k) and is_duplicate(hands[j], hands[k])
                                     for j in kept):
            kept.append(k)
    sides = {k: side_of(k) for k in kept}
    if len(kept) == 2:
        first, second = kept
        sides[first], sides[second] = ((RIGHT, LEFT) if odds[first] > odds[second] else
                                       (LEFT, RIGHT) if odds[first] < odds[second] else
                                       (sides[first], OTHER_SIDE[sides[first]]))
    out = tuple(Detection2D(sides[k], hands[k].joints_2d, hands[k].joint_confidence,
                            hands[k].confidence, hands[k].joints_metric) for k in kept)
    return SideDecision(out, tuple(kept), len(hands) - len(kept),
                        sum(sides[k] != hands[k].side for k in kept))
