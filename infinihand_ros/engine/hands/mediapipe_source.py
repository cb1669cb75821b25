"""The real-image hand source: MediaPipe Hands lifted to camera-space MANO hands.

Per frame: MediaPipe (``mediapipe_detector.py``) finds at most two hands with 21 landmarks,
metric hand-relative joints, handedness and a score. Hands scoring under
``hands.min_confidence`` are dropped (counted). Each hand's side is decided from MediaPipe's
label, on a head-mounted view (``hands.egocentric``) the arm's side of entry, and the hand's
history (``side.py``); at most one hand per side is kept (a hand seen twice is dropped,
counted). Each kept hand is lifted
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
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.hands.config import MEDIAPIPE
from infinihand_ros.engine.hands.detections import FrameDetections
from infinihand_ros.engine.hands.lift import lift_hand
from infinihand_ros.engine.hands.mediapipe_detector import MediaPipeDetector
from infinihand_ros.engine.hands.side import SideTracker
from infinihand_ros.mano.base import HandModel
from infinihand_ros.mano.fit import float64_copies
import numpy as np

#: Recent reprojection errors kept for the statistics.
RATIOS_KEPT: Final = 1000


class MediaPipeHandSource:
    """MediaPipe Hands lifted to MANO; the model's mask head and hand branch are not used."""

    name = MEDIAPIPE
    uses_hand_branch = False
    needs_image = True
    decides_sides = True

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
        self._sides = SideTracker(config.egocentric, config.mirrored)
        self.counts = {'frames': 0, 'found': 0, 'hands': 0, 'dropped_confidence': 0,
                       'dropped_duplicate': 0, 'relabelled': 0}
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
        if detections.scene_cut:  # a new scene: no warm start, no hand followed from the last
            self._previous.clear()
            self._sides.reset()
        self.counts['found'] += len(detections.hands)
        confident = [d for d in detections.hands if d.confidence >= self.config.min_confidence]
        self.counts['dropped_confidence'] += len(detections.hands) - len(confident)
        decision = self._sides.decide(confident, intrinsics.width, intrinsics.height)
        self.counts['dropped_duplicate'] += decision.duplicates
        self.counts['relabelled'] += decision.relabelled
        hands = []
        for found in decision.hands:
            lifted = lift_hand(found.side, found.joints_2d, found.joints_metric, found.confidence,
                               intrinsics, self._models[found.side],
                               self._previous.get(found.side), self.config.refine_iterations,
                               self.config.ray_passes)
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
        """Restart MediaPipe's tracking, the warm starts and the followed sides."""
        self._detector.reset()
        self._previous.clear()
        self._sides.reset()

    def close(self) -> None:
        """Release MediaPipe."""
        self._detector.close()
