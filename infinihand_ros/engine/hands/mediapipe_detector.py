"""MediaPipe Hands on a video stream, handedness in our convention, any image size.

Wraps ``data/mediapipe_source.py`` (the 0.10.21 wheel's palm and landmark models, offline on a
CPU) in its video mode: after a first detection MediaPipe tracks each hand from frame to frame
and skips the palm detector, as it does for a webcam. MediaPipe reads handedness as in a
mirrored selfie image; on ordinary images its labels are swapped into ours, with
``hands.mirrored`` they are kept. Images larger than ``MAX_SIDE_PX`` are downscaled for
MediaPipe (its models run at 192-256 px anyway) and the landmarks scaled back. At a cut between
scenes (consecutive images whose hue-saturation histograms differ by more than
``hands.scene_cut_distance``) the tracking restarts, so no hand is carried into a new scene.
"""

from collections.abc import Sequence
from dataclasses import replace
from typing import Final

import cv2
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.data.keypoint_source import Detection2D
from infinihand_ros.data.mediapipe_source import MediaPipeConfig
from infinihand_ros.data.mediapipe_source import MediaPipeKeypointSource
from infinihand_ros.engine.hands.config import HandsConfig
import numpy as np

#: Longest image side handed to MediaPipe, pixels (larger images are downscaled first).
MAX_SIDE_PX: Final = 1280
#: Histogram bins (hue, saturation) and the thumbnail width the scene-cut test uses.
CUT_BINS: Final = (16, 16)
CUT_THUMBNAIL_PX: Final = 160


def colour_histogram(image: np.ndarray) -> np.ndarray:
    """Return the normalised hue-saturation histogram of an RGB uint8 image (a thumbnail's)."""
    height, width = image.shape[:2]
    if width > CUT_THUMBNAIL_PX:
        size = (CUT_THUMBNAIL_PX, max(1, round(height * CUT_THUMBNAIL_PX / width)))
        image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    hsv = cv2.cvtColor(image, cv2.COLOR_RGB2HSV)
    histogram = cv2.calcHist([hsv], [0, 1], None, list(CUT_BINS), [0, 180, 0, 256])
    return cv2.normalize(histogram, histogram).ravel()


def histogram_distance(first: np.ndarray, second: np.ndarray) -> float:
    """Return the Bhattacharyya distance of two histograms (0 alike .. 1 disjoint)."""
    return float(cv2.compareHist(first, second, cv2.HISTCMP_BHATTACHARYYA))


class MediaPipeDetector:
    """MediaPipe Hands in video mode (one stream; ``reset`` between streams)."""

    def __init__(self, config: HandsConfig) -> None:
        """Load MediaPipe (InputError naming the install line when it cannot be imported)."""
        self.config = config
        self._settings = MediaPipeConfig(max_num_hands=2,
                                         model_complexity=config.model_complexity,
                                         min_detection_confidence=config.min_detection_confidence,
                                         static_image_mode=False)
        self._source = self._start()
        self._histogram: np.ndarray | None = None
        self.scene_cuts = 0
        self.cut = False  # the last image followed a cut (tracking restarted)

    def _start(self) -> MediaPipeKeypointSource:
        return MediaPipeKeypointSource(self._settings,
                                       self.config.min_tracking_confidence)

    def detect(self, image: np.ndarray, frame_index: int) -> Sequence[Detection2D]:
        """Return the hands in an RGB uint8 image, sides in our convention, source pixels."""
        if self.config.scene_cut_distance < 1.0:  # 1: never a cut, nothing to compare
            histogram = colour_histogram(image)
            self.cut = (self._histogram is not None and histogram_distance(
                self._histogram, histogram) > self.config.scene_cut_distance)
            if self.cut:
                self._restart()
                self.scene_cuts += 1
            self._histogram = histogram
        height, width = image.shape[:2]
        scale = min(1.0, MAX_SIDE_PX / max(height, width))
        small = image if scale == 1.0 else cv2.resize(
            image, (max(1, round(width * scale)), max(1, round(height * scale))),
            interpolation=cv2.INTER_AREA)
        found = self._source.detect(small, frame_index)
        if scale != 1.0:
            factor = np.array([width / small.shape[1], height / small.shape[0]])
            found = [replace(hand, joints_2d=hand.joints_2d * factor) for hand in found]
        if self.config.mirrored:  # the source swapped MediaPipe's selfie labels: undo it
            found = [replace(hand, side=RIGHT if hand.side == LEFT else LEFT) for hand in found]
        return found

    def reset(self) -> None:
        """Forget the tracked hands and the last image (a new stream)."""
        self._restart()
        self._histogram = None
        self.cut = False

    def _restart(self) -> None:
        """Restart MediaPipe's tracking."""
        self._source.close()
        self._source = self._start()

    def close(self) -> None:
        """Release MediaPipe."""
        self._source.close()
