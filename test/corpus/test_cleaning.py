"""Cleaning by 2D-keypoint consistency on a noisy synthetic corpus (``data/cleaning.py``)."""

from pathlib import Path

from infinihand_ros.core.config import load_config
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.geometry import project_points
from infinihand_ros.corpus.cleaning import clean_sequence
from infinihand_ros.corpus.cleaning import CleaningConfig
from infinihand_ros.corpus.cleaning import CleaningReport
from infinihand_ros.corpus.cleaning import DISCARD
from infinihand_ros.corpus.cleaning import KEEP
from infinihand_ros.corpus.cleaning import REVIEW
from infinihand_ros.corpus.cleaning import SequenceLabels
from infinihand_ros.corpus.hand_masks import capsule_masks
from infinihand_ros.corpus.hand_masks import masks_to_boxes
from infinihand_ros.engine.hands.keypoints import SyntheticKeypointSource
from infinihand_ros.mano.capsules import joint_radii
from infinihand_ros.synth.known_tracks import known_track
import numpy as np
import pytest

CONFIG = Path(__file__).resolve().parents[2] / 'config' / 'corpus.yaml'
FRAMES = 12
WIDTH, HEIGHT = 320, 240
K = np.array([[250.0, 0.0, 160.0], [0.0, 250.0, 120.0], [0.0, 0.0, 1.0]])
NOISE_PX = 2.0
#: Corruption of each sequence of the corpus (None = clean annotations).
CORRUPTIONS = (None, None, 'lag', None, 'offset', None, None, 'lag', None, 'offset')


def _truth(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera joints (T, 2, 21, 3), 2D joints (T, 2, 21, 2) and boxes (T, 2, 4) of two hands."""
    rng = np.random.default_rng(seed)
    tracks = [known_track(rng, side, FRAMES) for side in (0, 1)]
    joints = np.stack([track.joints for track in tracks], axis=1)
    radii = np.stack([joint_radii(track.betas) for track in tracks])
    boxes = np.stack([masks_to_boxes(capsule_masks(frame, radii, np.ones(2, bool), K, WIDTH,
                                                   HEIGHT)) for frame in joints])
    return joints, project_points(joints, K), boxes


def _corrupt(kind: str | None, joints: np.ndarray, joints_2d: np.ndarray,
             boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Annotations as a flawed dataset might give them: lagging, or shifted off the hand."""
    if kind == 'lag':  # annotations four frames behind the video
        return np.concatenate([joints[:1].repeat(4, 0), joints[:-4]]), \
            np.concatenate([joints_2d[:1].repeat(4, 0), joints_2d[:-4]])
    if kind == 'offset':  # annotated joints a fifth of the box beside the hand
        extent = (boxes[..., 2] - boxes[..., 0])[..., None, None]
        return joints, joints_2d + 0.2 * extent * np.array([1.0, 0.0])
    return joints, joints_2d


def _sequence(index: int, kind: str | None, config: CleaningConfig,
              confidence: float = 0.9) -> tuple:
    joints, joints_2d, boxes = _truth(100 + index)
    ann_joints, ann_2d = _corrupt(kind, joints, joints_2d, boxes)
    visible = np.all(boxes[..., 2:] > boxes[..., :2], axis=-1)
    labels = SequenceLabels(f'seq{index:02d}', ann_2d, ann_joints, boxes, visible)
    source = SyntheticKeypointSource(joints_2d, visible, NOISE_PX, seed=index,
                                     confidence=confidence)
    detections = [source.detect(np.zeros((HEIGHT, WIDTH, 3), np.uint8), i)
                  for i in range(FRAMES)]
    return clean_sequence(labels, detections, config)


def test_cleaning_removes_corrupted_and_keeps_clean_sequences() -> None:
    """At the configured settings exactly the corrupted sequences are removed (40 %)."""
    config = load_config(CONFIG, 'cleaning', CleaningConfig)
    report = CleaningReport(tuple(_sequence(i, kind, config)
                                  for i, kind in enumerate(CORRUPTIONS)))
    corrupted = [f'seq{i:02d}' for i, kind in enumerate(CORRUPTIONS) if kind]
    assert sorted(report.ids(DISCARD) + report.ids(REVIEW)) == corrupted
    assert report.ids(DISCARD) == corrupted
    assert report.removed_fraction() == pytest.approx(0.4)
    summary = report.summary()
    assert summary['counts'] == {KEEP: 6, REVIEW: 0, DISCARD: 4}
    kept = next(s for s in summary['sequences'] if s['sequence'] == 'seq00')
    assert kept['hands']['left']['score'] < config.review_threshold
    assert kept['hands']['left']['evaluated'] == kept['hands']['left']['annotated'] > 0


def test_uncertain_band_goes_to_review() -> None:
    """A score between the thresholds puts the sequence on the review list, not the bin."""
    probe = _sequence(4, 'offset', CleaningConfig(review_threshold=10.0,
                                                  discard_threshold=10.0))
    score = max(hand.score for hand in probe.hands)
    config = CleaningConfig(review_threshold=0.5 * score, discard_threshold=2.0 * score)
    verdict = _sequence(4, 'offset', config)
    assert verdict.decision == REVIEW
    assert 'in (' in verdict.reason


def test_low_confidence_detections_are_left_out_and_reviewed() -> None:
    """Detections under the confidence floor are not compared; too few left -> review."""
    verdict = _sequence(2, 'lag', CleaningConfig(), confidence=0.2)
    assert verdict.decision == REVIEW
    assert all(hand.evaluated == 0 for hand in verdict.hands)
    assert all(hand.excluded['low_confidence'] == hand.annotated for hand in verdict.hands)


def test_wrong_side_and_implausible_hands_are_left_out() -> None:
    """Detections labelled with the other side, and collapsed annotated hands, do not count."""
    joints, joints_2d, boxes = _truth(7)
    visible = np.ones((FRAMES, 2), bool)
    collapsed = joints.copy()
    collapsed[:3, 0] = collapsed[:3, 0, :1]  # every left joint on the wrist: no bones
    labels = SequenceLabels('swap', joints_2d, collapsed, boxes, visible)
    swapped = SyntheticKeypointSource(joints_2d[:, ::-1], visible, NOISE_PX, seed=1)
    detections = [[type(d)(1 - d.side, d.joints_2d, d.joint_confidence, d.confidence)
                   for d in swapped.detect(None, i)] for i in range(FRAMES)]
    verdict = clean_sequence(labels, detections, CleaningConfig())
    left, right = verdict.hands
    assert left.excluded['implausible_pose'] == 3
    assert left.evaluated == FRAMES - 3 and right.evaluated == FRAMES
    assert verdict.decision == KEEP


def test_config_rejects_review_above_discard() -> None:
    """A review threshold above the discard threshold is a ConfigError naming both."""
    with pytest.raises(ConfigError, match='review_threshold 0.3 must not exceed'):
        CleaningConfig(review_threshold=0.3, discard_threshold=0.2)
