"""The real-image hand source: MediaPipe Hands lifted to camera-space MANO hands.

Per frame: MediaPipe (``mediapipe_detector.py``) finds at most two hands with 21 landmarks,
metric hand-relative joints, handedness and a score. Hands scoring under
``hands.min_confidence`` are dropped (counted). At most one hand per side is kept: of two hands
labelled alike, the weaker takes the free side unless it is the stronger one seen twice (boxes
overlapping, or wrists nearly coinciding), and then it is dropped. Each kept hand is lifted
(``lift.py``) with the frame's intrinsics, its shape and fit warm-started from the same side's
previous hand. The landmark box is the hand's box and MediaPipe's handedness score its
confidence.
"""

from collections import deque
from collections.abc import Sequence
from typing import Final

from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.core.hand_conventions import WRIST
from infinihand_ros.engine.hands.boxes import box_iou
from infinihand_ros.engine.hands.boxes import landmark_box
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.hands.config import MEDIAPIPE
from infinihand_ros.engine.hands.detections import FrameDetections
from infinihand_ros.engine.hands.keypoints import Detection2D
from infinihand_ros.engine.hands.lift import lift_hand
from infinihand_ros.engine.hands.mediapipe_detector import MediaPipeDetector
from infinihand_ros.mano.base import HandModel
from infinihand_ros.mano.fit import float64_copies
import numpy as np

#: Two same-labelled hands overlapping more than this (IoU), or with wrists closer than
#: ``DUPLICATE_WRIST_FRACTION`` of the hand's box size, are one hand seen twice.
DUPLICATE_IOU: Final = 0.5
DUPLICATE_WRIST_FRACTION: Final = 0.25
#: Recent reprojection errors kept for the statistics.
RATIOS_KEPT: Final = 1000


def is_duplicate(a: Detection2D, b: Detection2D) -> bool:
    """Return whether two detections are one hand (boxes overlap, or wrists nearly coincide)."""
    box_a, box_b = landmark_box(a.joints_2d), landmark_box(b.joints_2d)
    size = max(np.ptp(a.joints_2d, axis=0).max(), np.ptp(b.joints_2d, axis=0).max(), 1.0)
    wrists = float(np.linalg.norm(a.joints_2d[WRIST] - b.joints_2d[WRIST]))
    return box_iou(box_a, box_b) > DUPLICATE_IOU or wrists < DUPLICATE_WRIST_FRACTION * size


def one_per_side(detections: Sequence[Detection2D]) -> list[Detection2D]:
    """Return at most one detection per side (see the module docstring), strongest first."""
    kept: list[Detection2D] = []
    for found in sorted(detections, key=lambda d: -d.confidence):
        taken = {hand.side for hand in kept}
        if found.side not in taken:
            kept.append(found)
            continue
        other = next(hand for hand in kept if hand.side == found.side)
        free = ({LEFT, RIGHT} - taken)
        if free and not is_duplicate(found, other):
            kept.append(Detection2D(free.pop(), found.joints_2d, found.joint_confidence,
                                    found.confidence, found.joints_metric))
    return kept


class MediaPipeHandSource:
    """MediaPipe Hands lifted to MANO; the model's mask head and hand branch are not used."""

    name = MEDIAPIPE
    uses_hand_branch = False
    needs_image = True

    def __init__(self, config: HandsConfig, hand_models: Sequence[HandModel]) -> None:
        """Start MediaPipe (at start-up: InputError naming the install line if it is missing).

        Args:
            config: the hands settings.
            hand_models: (left, right) hand models (copied to float64 for the fit).

        """
        self.config = config
        self._models = float64_copies(hand_models)
        self._detector = MediaPipeDetector(config)
        self._previous: dict[int, ManoParams] = {}
        self.counts = {'frames': 0, 'hands': 0, 'dropped_confidence': 0,
                       'dropped_duplicate': 0}
        self.reprojection_ratios: deque[float] = deque(maxlen=RATIOS_KEPT)

    def detect(self, image: np.ndarray, frame_index: int) -> FrameDetections:
        """Run MediaPipe on the frame's source image (and tell whether a scene starts)."""
        found = self._detector.detect(image, frame_index)
        return FrameDetections(tuple(found), self._detector.cut)

    def camera_hands(self, detections: FrameDetections,
                     branch_hands: tuple[HandState, ...], intrinsics: Intrinsics
                     ) -> tuple[HandState, ...]:
        """Return the frame's lifted hands, at most one per side, confident enough."""
        self.counts['frames'] += 1
        if detections.scene_cut:  # a new scene: no warm start from the last one
            self._previous.clear()
        confident = [d for d in detections.hands if d.confidence >= self.config.min_confidence]
        self.counts['dropped_confidence'] += len(detections.hands) - len(confident)
        kept = one_per_side(confident)
        self.counts['dropped_duplicate'] += len(confident) - len(kept)
        hands = []
        for found in kept:
            lifted = lift_hand(found.side, found.joints_2d, found.joints_metric, found.confidence,
                               intrinsics, self._models[found.side],
                               self._previous.get(found.side), self.config.refine_iterations)
            self._previous[found.side] = lifted.hand.mano_cam
            self.reprojection_ratios.append(lifted.reprojection_px /
                                            max(lifted.box_size_px, 1.0))
            hands.append(lifted.hand)
        for side in set(self._previous) - {hand.side for hand in hands}:
            del self._previous[side]  # a hand that left starts afresh when it comes back
        self.counts['hands'] += len(hands)
        return tuple(sorted(hands, key=lambda hand: hand.side))

    def statistics(self) -> dict[str, object]:
        """Return the counters and the recent reprojection error (fraction of the box size)."""
        ratios = self.reprojection_ratios
        return {'source': self.name, **self.counts, 'scene_cuts': self._detector.scene_cuts,
                'reprojection_box_fraction_p95': (float(np.percentile(ratios, 95)) if ratios
                                                  else None)}

    def reset(self) -> None:
        """Restart MediaPipe's tracking and the warm starts."""
        self._detector.reset()
        self._previous.clear()

    def close(self) -> None:
        """Release MediaPipe."""
        self._detector.close()
