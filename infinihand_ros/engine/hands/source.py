"""The engine's hand-source seam: where camera-space hands come from.

One interface (``HandSource``), one module per source:

- ``InfiniHandSource``: the paper's hand branch (mask head, crops, MANO head, eq. 5) inside the
  model, as trained; its hands pass when confident enough and, with ``hands.verify``, only where
  MediaPipe finds a hand of the same side at the same place (the guard against images unlike
  the bundled model's synthetic training data);
- ``MediaPipeHandSource`` (``mediapipe_source.py``): MediaPipe Hands on the source image, each
  hand lifted to the same camera-space MANO hand (``lift.py``).

The engine calls ``detect`` when a frame is pushed (with its source image, when ``needs_image``)
and ``camera_hands`` once the frame's intrinsics are known (given or predicted) and, for the
infinihand source, the hand branch has run. A new source is one module implementing these
calls and one entry in ``build_hand_source``.
"""

from collections.abc import Sequence
from typing import Protocol

from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.engine.hands.boxes import box_iou
from infinihand_ros.engine.hands.boxes import landmark_box
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.hands.config import INFINIHAND
from infinihand_ros.engine.hands.detections import FrameDetections
from infinihand_ros.engine.hands.mediapipe_detector import MediaPipeDetector
from infinihand_ros.engine.hands.mediapipe_source import MediaPipeHandSource
from infinihand_ros.mano.base import HandModel
import numpy as np


class HandSource(Protocol):
    """What the engine asks of a hand source (one stream, frames in order)."""

    name: str
    #: Whether the model's mask head and hand branch find the hands (else they are not run).
    uses_hand_branch: bool
    #: Whether ``detect`` needs each frame's source image.
    needs_image: bool
    #: Whether the source keeps each hand's side over time itself (the output stage's
    #: identity then relabels nothing).
    decides_sides: bool

    def detect(self, image: np.ndarray, frame_index: int) -> FrameDetections:
        """Look at a pushed frame's source image (RGB uint8); return what camera_hands needs.

        Called in the engine's detection thread, frame by frame in order; it must not change
        what ``camera_hands`` reads (that runs on another thread, possibly a frame behind).
        """

    def camera_hands(self, detections: FrameDetections,
                     branch_hands: tuple[HandState, ...], intrinsics: Intrinsics
                     ) -> tuple[HandState, ...]:
        """Return the frame's camera-space hands (at most one per side) that count."""

    def statistics(self) -> dict[str, object]:
        """Return counters for diagnostics and reports (frames, hands, drops by cause)."""

    def reset(self) -> None:
        """Start a new stream."""

    def close(self) -> None:
        """Release what the source holds; idempotent."""


class InfiniHandSource:
    """The paper's hand branch, gated by confidence and optionally verified by MediaPipe."""

    name = INFINIHAND
    uses_hand_branch = True
    decides_sides = False

    def __init__(self, config: HandsConfig) -> None:
        """Start MediaPipe too when ``config.verify`` asks for the guard."""
        self.config = config
        self.needs_image = config.verify
        self._detector = MediaPipeDetector(config) if config.verify else None
        self.counts = {'frames': 0, 'found': 0, 'hands': 0, 'dropped_confidence': 0,
                       'dropped_verify': 0}

    def detect(self, image: np.ndarray, frame_index: int) -> FrameDetections:
        """Run MediaPipe for the guard (nothing without ``verify``)."""
        if self._detector is None:
            return FrameDetections()
        found = self._detector.detect(image, frame_index)
        return FrameDetections(tuple(found), self._detector.cut)

    def camera_hands(self, detections: FrameDetections,
                     branch_hands: tuple[HandState, ...], intrinsics: Intrinsics
                     ) -> tuple[HandState, ...]:
        """Return the branch's hands that are confident enough (and verified, with the guard)."""
        self.counts['frames'] += 1
        self.counts['found'] += len(branch_hands)
        kept = []
        for hand in branch_hands:
            if hand.confidence < self.config.min_confidence:
                self.counts['dropped_confidence'] += 1
            elif self._detector is not None and not self._verified(hand, detections):
                self.counts['dropped_verify'] += 1
            else:
                kept.append(hand)
        self.counts['hands'] += len(kept)
        return tuple(kept)

    def _verified(self, hand: HandState, detections: FrameDetections) -> bool:
        """Return whether MediaPipe found a hand of the same side overlapping this one."""
        for found in detections.hands:
            overlap = box_iou(landmark_box(found.joints_2d), hand.box_xyxy)
            if found.side == hand.side and overlap >= self.config.verify_min_iou:
                return True
        return False

    def statistics(self) -> dict[str, object]:
        """Return the counters."""
        return {'source': self.name, 'verify': self.config.verify, **self.counts}

    def reset(self) -> None:
        """Restart MediaPipe's tracking (counters keep counting)."""
        if self._detector is not None:
            self._detector.reset()

    def close(self) -> None:
        """Release MediaPipe."""
        if self._detector is not None:
            self._detector.close()


def build_hand_source(config: HandsConfig, hand_models: Sequence[HandModel]) -> HandSource:
    """Return the hand source ``config.source`` names (MediaPipe starts here, at start-up).

    Raises:
        InputError: when MediaPipe is needed and cannot be imported (naming the install line).

    """
    if config.source == INFINIHAND:
        return InfiniHandSource(config)
    return MediaPipeHandSource(config, hand_models)
