"""Independent 2D hand-keypoint sources for the cleaning step (paper Sec. 3.1 uses Sapiens 2).

A source looks at one RGB frame and returns the hands it finds, each with a side, 21 joints in
pixels (OpenPose order) and confidences. ``SyntheticKeypointSource`` is the test double: it
returns known 2D joints with seeded Gaussian noise, so cleaning can be checked exactly.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import SIDES
import numpy as np


@dataclass(frozen=True)
class Detection2D:
    """One hand found by a 2D source.

    Attributes:
        side: 0 left, 1 right, in our convention (not a mirrored selfie view).
        joints_2d: (21, 2) pixels, OpenPose order.
        joint_confidence: (21,) scores in [0, 1].
        confidence: detection score in [0, 1].
        joints_metric: (21, 3) metric joints in a hand-centred frame whose axes follow the
            image's (metres), when the source estimates them, else None.

    """

    side: int
    joints_2d: np.ndarray
    joint_confidence: np.ndarray
    confidence: float
    joints_metric: np.ndarray | None = None


class KeypointSource(Protocol):
    """Anything that finds hands and their 2D joints in a frame."""

    def detect(self, rgb: np.ndarray, frame_index: int) -> Sequence[Detection2D]:
        """Return the hands in ``rgb`` ((H, W, 3) uint8), frame ``frame_index`` of a sequence."""


class SyntheticKeypointSource:
    """Known 2D joints plus seeded noise: a detector whose errors are chosen by the test."""

    def __init__(self, joints_2d: np.ndarray, present: np.ndarray, noise_px: float,
                 seed: int, confidence: float = 0.9) -> None:
        """Hold the truth of a sequence.

        Args:
            joints_2d: (T, 2, 21, 2) true joints per side [left, right], pixels.
            present: (T, 2) bool, the hand is there to be found.
            noise_px: standard deviation of the Gaussian pixel noise per coordinate.
            seed: seed of the noise (frame ``i`` draws from ``(seed, i)``).
            confidence: score given to every detection and joint.

        Raises:
            InputError: for arrays of the wrong shape or negative noise.

        """
        joints = np.asarray(joints_2d, np.float64)
        if joints.ndim != 4 or joints.shape[1:] != (len(SIDES), NUM_JOINTS, 2):
            raise InputError(f'joints_2d: expected shape (T, 2, 21, 2), got {joints.shape}')
        flags = np.asarray(present, bool)
        if flags.shape != joints.shape[:2]:
            raise InputError(f'present: expected shape {joints.shape[:2]}, got {flags.shape}')
        if noise_px < 0:
            raise InputError(f'noise_px must be >= 0, got {noise_px}')
        self._joints, self._present = joints, flags
        self._noise_px, self._seed, self._confidence = noise_px, seed, confidence

    def detect(self, rgb: np.ndarray, frame_index: int) -> list[Detection2D]:
        """Return the noisy true hands of frame ``frame_index`` (``rgb`` is not looked at)."""
        rng = np.random.default_rng([self._seed, frame_index])
        found = []
        for side in SIDES:
            if not self._present[frame_index, side]:
                continue
            noise = rng.normal(scale=self._noise_px, size=(NUM_JOINTS, 2))
            found.append(Detection2D(side, self._joints[frame_index, side] + noise,
                                     np.full(NUM_JOINTS, self._confidence), self._confidence))
        return found
