"""Sequence cleaning by 2D-keypoint consistency, as paper Sec. 3.1 describes.

For each annotated hand of each frame the independent 2D source's detection of the same side
is looked up. The hand-frame is left out of the evaluation when the detection's confidence is
low, when the association is invalid (no detection of that side, or one whose joints' box does
not overlap the annotated box) or when the annotated pose is anatomically implausible. For the
rest, joint-wise pixel errors between the detection and the projected annotated joints are
normalised by the annotated box's extent (its longer side) and averaged over the joints. Each
hand's sequence score is the 90th percentile of these frame errors. A sequence is discarded
when either hand's score exceeds the discard threshold, set aside for review when one falls in
the band between the review and discard thresholds (or too few frames could be evaluated), and
kept otherwise. The paper gives no threshold values; ours are in ``config/corpus.yaml``.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from dataclasses import field
from typing import Final

from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.hand_conventions import SIDE_NAMES
from infinihand_ros.core.hand_conventions import SIDES
from infinihand_ros.corpus.plausibility import PlausibilityConfig
from infinihand_ros.corpus.plausibility import plausible_hands
from infinihand_ros.engine.hands.keypoints import Detection2D
import numpy as np

KEEP: Final = 'keep'
REVIEW: Final = 'review'
DISCARD: Final = 'discard'
#: Why a hand-frame was left out of the evaluation (keys of ``HandScore.excluded``).
EXCLUSION_REASONS: Final = ('low_confidence', 'invalid_association', 'implausible_pose')


@dataclass(frozen=True)
class CleaningConfig:
    """Cleaning settings (``config/corpus.yaml``, section ``cleaning``).

    Attributes:
        min_confidence: detections scoring lower are left out.
        min_joint_confidence: detected joints scoring lower do not count in the error.
        min_association_iou: least IoU of the detection's joint box and the annotated box.
        percentile: sequence summary of the per-frame errors (the paper's 90th).
        review_threshold: normalised error above which a sequence goes to review.
        discard_threshold: normalised error above which a sequence is discarded.
        min_evaluated_fraction: a hand with annotations in fewer evaluable frames than this
            fraction goes to review.
        plausibility: anatomical limits.

    """

    min_confidence: float = 0.5
    min_joint_confidence: float = 0.3
    min_association_iou: float = 0.1
    percentile: float = 90.0
    review_threshold: float = 0.08
    discard_threshold: float = 0.12
    min_evaluated_fraction: float = 0.3
    plausibility: PlausibilityConfig = field(default_factory=PlausibilityConfig)

    def __post_init__(self) -> None:
        require_positive('cleaning', percentile=self.percentile,
                         review_threshold=self.review_threshold)
        if not self.review_threshold <= self.discard_threshold:
            raise ConfigError(f'cleaning: review_threshold {self.review_threshold} must not '
                              f'exceed discard_threshold {self.discard_threshold}')
        if not 0 < self.percentile <= 100:
            raise ConfigError(f'cleaning.percentile must be in (0, 100], got {self.percentile}')


@dataclass(frozen=True)
class SequenceLabels:
    """What cleaning needs of an annotated sequence (T frames, side axis [left, right]).

    Attributes:
        sequence_id: name of the sequence.
        joints_2d: (T, 2, 21, 2) projected annotated joints, pixels.
        joints_cam: (T, 2, 21, 3) annotated joints, camera frame, metres.
        box_xyxy: (T, 2, 4) annotated tight boxes, pixels (x1, y1 exclusive).
        visible: (T, 2) bool, the hand is annotated and visible.

    """

    sequence_id: str
    joints_2d: np.ndarray
    joints_cam: np.ndarray
    box_xyxy: np.ndarray
    visible: np.ndarray


@dataclass(frozen=True)
class HandScore:
    """Cleaning figures of one hand of a sequence.

    Attributes:
        frame_errors: (T,) normalised errors, NaN where the hand-frame was not evaluated.
        score: the percentile of the evaluated frame errors (NaN if none).
        annotated: frames where the hand is annotated and visible.
        evaluated: frames that entered the score.
        excluded: counts of frames left out, by ``EXCLUSION_REASONS``.

    """

    frame_errors: np.ndarray
    score: float
    annotated: int
    evaluated: int
    excluded: dict[str, int]


@dataclass(frozen=True)
class SequenceVerdict:
    """The decision on one sequence and why."""

    sequence_id: str
    decision: str
    reason: str
    hands: tuple[HandScore, HandScore]

    def summary(self) -> dict:
        """Return the verdict as JSON-ready data (no per-frame arrays)."""
        return {'sequence': self.sequence_id, 'decision': self.decision, 'reason': self.reason,
                'hands': {SIDE_NAMES[side]: {
                    'score': None if np.isnan(hand.score) else float(hand.score),
                    'annotated': hand.annotated, 'evaluated': hand.evaluated,
                    'excluded': dict(hand.excluded)} for side, hand in enumerate(self.hands)}}


def _box_iou(box_a: np.ndarray, box_b: np.ndarray) -> float:
    """Return the intersection over union of two (x0, y0, x1, y1) boxes."""
    width = min(box_a[2], box_b[2]) - max(box_a[0], box_b[0])
    height = min(box_a[3], box_b[3]) - max(box_a[1], box_b[1])
    inter = max(width, 0.0) * max(height, 0.0)
    area = (box_a[2] - box_a[0]) * (box_a[3] - box_a[1]) + (box_b[2] - box_b[0]) * (
        box_b[3] - box_b[1]) - inter
    return inter / area if area > 0 else 0.0


def _frame_error(detection: Detection2D | None, joints_2d: np.ndarray, box: np.ndarray,
                 plausible: bool, config: CleaningConfig) -> tuple[float, str | None]:
    """Normalised error of one annotated hand-frame, or NaN and the reason it was left out."""
    if detection is None:
        return np.nan, 'invalid_association'
    if detection.confidence < config.min_confidence:
        return np.nan, 'low_confidence'
    points = np.asarray(detection.joints_2d)
    detected_box = np.concatenate([points.min(axis=0), points.max(axis=0)])
    if _box_iou(detected_box, box) < config.min_association_iou:
        return np.nan, 'invalid_association'
    if not plausible:
        return np.nan, 'implausible_pose'
    use = np.asarray(detection.joint_confidence) >= config.min_joint_confidence
    if not use.any():
        return np.nan, 'low_confidence'
    extent = max(box[2] - box[0], box[3] - box[1])
    errors = np.linalg.norm(points - joints_2d, axis=-1)[use]
    return float(errors.mean() / extent), None


def score_hand(labels: SequenceLabels, detections: Sequence[Sequence[Detection2D]], side: int,
               config: CleaningConfig) -> HandScore:
    """Score one side of a sequence against the 2D source's detections of every frame."""
    frames = len(labels.visible)
    plausible = plausible_hands(labels.joints_cam[:, side], config.plausibility)
    errors = np.full(frames, np.nan)
    excluded = dict.fromkeys(EXCLUSION_REASONS, 0)
    annotated = 0
    for index in range(frames):
        box = labels.box_xyxy[index, side]
        if not labels.visible[index, side] or box[2] <= box[0] or box[3] <= box[1]:
            continue
        annotated += 1
        same_side = [d for d in detections[index] if d.side == side]
        detection = max(same_side, key=lambda d: d.confidence) if same_side else None
        errors[index], reason = _frame_error(detection, labels.joints_2d[index, side], box,
                                             bool(plausible[index]), config)
        if reason is not None:
            excluded[reason] += 1
    evaluated = int(np.sum(~np.isnan(errors)))
    score = float(np.percentile(errors[~np.isnan(errors)], config.percentile)) \
        if evaluated else float('nan')
    return HandScore(errors, score, annotated, evaluated, excluded)


def _decide(hands: tuple[HandScore, HandScore], config: CleaningConfig) -> tuple[str, str]:
    """Return (decision, reason) from the two hands' scores."""
    scored = [(SIDE_NAMES[side], hand) for side, hand in enumerate(hands) if hand.evaluated]
    worst = [f'{name} p{config.percentile:g} {hand.score:.3f}' for name, hand in scored]
    if any(hand.score > config.discard_threshold for _, hand in scored):
        return DISCARD, f'{", ".join(worst)} > {config.discard_threshold:g}'
    if any(hand.score > config.review_threshold for _, hand in scored):
        return REVIEW, f'{", ".join(worst)} in ({config.review_threshold:g}, ' \
            f'{config.discard_threshold:g}]'
    thin = [SIDE_NAMES[side] for side, hand in enumerate(hands)
            if hand.annotated and hand.evaluated < config.min_evaluated_fraction * hand.annotated]
    if thin:
        return REVIEW, f'too few evaluable frames ({", ".join(thin)})'
    if not scored:
        return KEEP, 'no annotated visible hand to check'
    return KEEP, f'{", ".join(worst)} <= {config.review_threshold:g}'


def clean_sequence(labels: SequenceLabels, detections: Sequence[Sequence[Detection2D]],
                   config: CleaningConfig) -> SequenceVerdict:
    """Decide keep / review / discard for one sequence.

    Args:
        labels: the sequence's annotations.
        detections: per frame, the 2D source's hands (any number, any sides).
        config: thresholds.

    """
    hands = tuple(score_hand(labels, detections, side, config) for side in SIDES)
    decision, reason = _decide(hands, config)
    return SequenceVerdict(labels.sequence_id, decision, reason, hands)


@dataclass(frozen=True)
class CleaningReport:
    """Decisions over a corpus."""

    verdicts: tuple[SequenceVerdict, ...]

    def ids(self, decision: str) -> list[str]:
        """Return the sequence ids with ``decision``."""
        return [v.sequence_id for v in self.verdicts if v.decision == decision]

    def removed_fraction(self) -> float:
        """Fraction of the sequences not kept (discarded or set aside for review)."""
        return 1.0 - len(self.ids(KEEP)) / max(len(self.verdicts), 1)

    def summary(self) -> dict:
        """Return a JSON-ready report: counts, the review list and every verdict."""
        return {'counts': {d: len(self.ids(d)) for d in (KEEP, REVIEW, DISCARD)},
                'removed_fraction': self.removed_fraction(), 'review': self.ids(REVIEW),
                'sequences': [v.summary() for v in self.verdicts]}
