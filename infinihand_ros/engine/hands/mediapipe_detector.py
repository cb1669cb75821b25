"""MediaPipe Hands on a video stream, handedness in our convention, any image size.

Wraps ``data/mediapipe_source.py`` (the 0.10.21 wheel's palm and landmark models, offline on a
CPU) in its video mode: after a first detection MediaPipe tracks each hand from frame to frame
and skips the palm detector, as it does for a webcam. MediaPipe reads handedness as in a
mirrored selfie image; on ordinary images its labels are swapped into ours, with
``hands.mirrored`` they are kept. Images larger than ``MAX_SIDE_PX`` are downscaled for
MediaPipe (its models run at 192-256 px anyway) and the landmarks scaled back. At a cut between
scenes (``scene_cut.py``: not a fast turn or a blurred frame of the same scene) the tracking
restarts, so no hand is carried into a new scene.

MediaPipe's own video mode runs its palm detector on every frame on which it tracks fewer hands
than it may report, so with one hand in view it pays for a detection and a tracking each frame.
With ``hands.search_interval`` > 1 the work is split: where no hand is followed, MediaPipe in
image mode detects up to two hands (its palm detector, as the video mode would); from the next
frame a one-hand graph follows one of them (tracking only) and a second one-hand graph looks at
the image with that hand blanked out, on every frame while it follows a second hand and on every
``search_interval``-th frame otherwise (its palm detector runs only then), and on every frame
for ``LOST_SEARCH_FRAMES`` frames after fewer hands were found than on the frame before (a hand
lost in blur or behind something is found again as soon as it shows). Where the first graph
loses its hand while the second follows one, the two swap roles; where neither follows a hand
any more, the image is searched again in the same frame. The second graph runs beside the
first (in a helper thread; MediaPipe lets go of the GIL), so it looks at the image with the
first hand's box of the previous image blanked: on two cores a frame costs about one graph's
time.
"""

from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from typing import Final

import cv2
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.engine.hands.boxes import box_iou
from infinihand_ros.engine.hands.boxes import landmark_box
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.hands.keypoints import Detection2D
from infinihand_ros.engine.hands.mediapipe_keypoints import MediaPipeConfig
from infinihand_ros.engine.hands.mediapipe_keypoints import MediaPipeKeypointSource
from infinihand_ros.engine.hands.scene_cut import SceneCuts
import numpy as np

#: Longest image side handed to MediaPipe, pixels (larger images are downscaled first).
MAX_SIDE_PX: Final = 1280
#: The tracked hand's box, grown by this share of its size per side, is blanked for the search.
BLANK_MARGIN: Final = 0.25
#: A searched hand overlapping the tracked one more than this (IoU) is the same hand.
SAME_HAND_IOU: Final = 0.1
#: For this many frames after a hand is lost the second graph looks on every frame.
LOST_SEARCH_FRAMES: Final = 10


def blank_box(image: np.ndarray, box: np.ndarray, margin: float = BLANK_MARGIN) -> np.ndarray:
    """Return a copy of ``image`` with ``box`` (x0, y0, x1, y1), grown, in its mean colour."""
    height, width = image.shape[:2]
    grow = margin * np.array([box[0] - box[2], box[1] - box[3], box[2] - box[0],
                              box[3] - box[1]])
    x0, y0, x1, y1 = np.round(box + grow).astype(int)
    blanked = image.copy()
    blanked[max(y0, 0):min(y1, height), max(x0, 0):min(x1, width)] = (
        image.reshape(-1, image.shape[2]).mean(axis=0))
    return blanked


class MediaPipeDetector:
    """MediaPipe Hands in video mode (one stream; ``reset`` between streams)."""

    def __init__(self, config: HandsConfig) -> None:
        """Load MediaPipe (InputError naming the install line when it cannot be imported)."""
        self.config = config
        searching = config.search_interval > 1
        # MediaPipe as it is (two hands, its palm detector whenever fewer are tracked) ...
        self._pair = None if searching else self._start(max_num_hands=2)
        # ... or MediaPipe in image mode (no state) where no hand is followed, and two one-hand
        # graphs following the hands it found.
        self._search = self._start(max_num_hands=2, static=True) if searching else None
        self._first = self._start(max_num_hands=1) if searching else None
        self._second = self._start(max_num_hands=1) if searching else None
        # The second graph runs beside the first while both follow a hand.
        self._helper = (ThreadPoolExecutor(max_workers=1, thread_name_prefix='mediapipe_second')
                        if searching else None)
        self._had_hand = False  # the last image had a hand: the first graph follows it
        self._second_tracked = False  # the second graph follows a hand
        self._first_box: np.ndarray | None = None  # the first graph's hand in the last image
        self._since_search = 0
        self._since_lost = LOST_SEARCH_FRAMES  # frames since fewer hands were found than before
        self._last_count = 0  # hands found in the last image
        self._cuts = SceneCuts(config.scene_cut_distance)
        self.scene_cuts = 0
        self.cut = False  # the last image followed a cut (tracking restarted)

    def _start(self, max_num_hands: int, static: bool = False) -> MediaPipeKeypointSource:
        settings = MediaPipeConfig(max_num_hands=max_num_hands,
                                   model_complexity=self.config.model_complexity,
                                   min_detection_confidence=self.config.min_detection_confidence,
                                   static_image_mode=static)
        return MediaPipeKeypointSource(settings, self.config.min_tracking_confidence)

    def detect(self, image: np.ndarray, frame_index: int) -> Sequence[Detection2D]:
        """Return the hands in an RGB uint8 image, sides in our convention, source pixels."""
        if self.config.scene_cut_distance < 1.0:  # 1: never a cut, nothing to compare
            self.cut = self._cuts.is_cut(image)
            if self.cut:
                self._restart()
                self.scene_cuts += 1
        height, width = image.shape[:2]
        scale = min(1.0, MAX_SIDE_PX / max(height, width))
        small = image if scale == 1.0 else cv2.resize(
            image, (max(1, round(width * scale)), max(1, round(height * scale))),
            interpolation=cv2.INTER_AREA)
        found = self._track(small, frame_index)
        if scale != 1.0:
            factor = np.array([width / small.shape[1], height / small.shape[0]])
            found = [replace(hand, joints_2d=hand.joints_2d * factor) for hand in found]
        if self.config.mirrored:  # the source swapped MediaPipe's selfie labels: undo it
            found = [replace(hand, side=RIGHT if hand.side == LEFT else LEFT) for hand in found]
        return found

    def _track(self, image: np.ndarray, frame_index: int) -> list[Detection2D]:
        """Return MediaPipe's hands in ``image``, a second one searched for only at intervals."""
        if self._pair is not None:
            return self._pair.detect(image, frame_index)
        found = self._follow(image, frame_index)
        lost = len(found) < self._last_count
        self._since_lost = 0 if lost else self._since_lost + 1
        self._last_count = len(found)
        return found

    def _follow(self, image: np.ndarray, frame_index: int) -> list[Detection2D]:
        """Return the two one-hand graphs' hands (or the search's, where they follow none)."""
        due = (self._second_tracked or self._since_lost < LOST_SEARCH_FRAMES
               or self._since_search + 1 >= self.config.search_interval)
        beside = (self._helper.submit(self._second.detect, blank_box(image, self._first_box),
                                      frame_index)
                  if self._had_hand and due else None)  # the second graph, beside the first
        found = self._first.detect(image, frame_index) if self._had_hand else []
        seconds = [] if beside is None else beside.result()
        if not found and seconds:  # the first graph lost its hand, the second has one
            self._first, self._second = self._second, self._first
            self._first_box = landmark_box(seconds[0].joints_2d)
            self._second_tracked = False
            self._since_search = 0
            return seconds
        if not found:  # nothing followed, or lost since the last image: detect in this one
            found = self._search.detect(image, frame_index)
            self._had_hand, self._second_tracked = bool(found), len(found) > 1
            self._first_box = landmark_box(found[0].joints_2d) if found else None
            self._since_search = 0
            return found
        box = self._first_box = landmark_box(found[0].joints_2d)
        if beside is None:
            self._since_search += 1
            return found
        self._since_search = 0
        others = [hand for hand in seconds
                  if box_iou(box, landmark_box(hand.joints_2d)) <= SAME_HAND_IOU]
        self._second_tracked = bool(others)
        return [*found, *others]

    def reset(self) -> None:
        """Forget the tracked hands and the last image (a new stream)."""
        self._restart()
        self._cuts.reset()
        self.cut = False

    def _restart(self) -> None:
        """Restart MediaPipe's tracking (the graphs that keep a state)."""
        if self._pair is not None:
            self._pair.close()
            self._pair = self._start(max_num_hands=2)
        else:
            for graph in (self._first, self._second):
                graph.close()
            self._first, self._second = self._start(max_num_hands=1), self._start(max_num_hands=1)
        self._had_hand = self._second_tracked = False
        self._first_box = None
        self._since_search = self._last_count = 0
        self._since_lost = LOST_SEARCH_FRAMES

    def close(self) -> None:
        """Release MediaPipe."""
        if self._helper is not None:
            self._helper.shutdown(wait=True)
        for graph in (self._pair, self._first, self._second, self._search):
            if graph is not None:
                graph.close()
