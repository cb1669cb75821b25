"""Settings of the engine's hand source (``engine.hands``; the node's ``hands.*`` parameters)."""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.parameters import check_parameters
from infinihand_ros.core.parameters import parameter

INFINIHAND: Final = 'infinihand'
MEDIAPIPE: Final = 'mediapipe'
HAND_SOURCES: Final = (INFINIHAND, MEDIAPIPE)


@dataclass(frozen=True)
class HandsConfig:
    """Where the engine's camera-space hands come from, and which of them count."""

    source: str = parameter(MEDIAPIPE, "Hand source: infinihand (the paper's hand branch; the "
                            'bundled weights have seen only synthetic images); mediapipe '
                            '(MediaPipe Hands, trained on real photos, lifted to MANO).',
                            choices=HAND_SOURCES)
    min_confidence: float = parameter(0.5, "A hand is output only when its source's confidence "
                                      'is at least this.', 0.0, 1.0)
    mirrored: bool = parameter(False, 'The images are mirrored (a selfie view); handedness is '
                               'read accordingly.')
    egocentric: bool = parameter(True, "A head-mounted camera: with MediaPipe, a hand's side "
                                 "also follows its arm's side of entry (the wearer's right arm "
                                 'comes in from the lower right), which decides where '
                                 "MediaPipe's label is unsure. False for a third-person view "
                                 '(the teleop profile).')
    verify: bool = parameter(False, 'With the infinihand source: keep a hand only where '
                             'MediaPipe finds one of the same side at the same place (a guard '
                             'against images unlike the training data).')
    verify_min_iou: float = parameter(0.3, 'With verify: the least box overlap (IoU) that counts '
                                      'as the same place.', 0.0, 1.0)
    model_complexity: int = parameter(1, 'MediaPipe landmark model: 0 lite (faster), 1 full.',
                                      0, 1)
    min_detection_confidence: float = parameter(0.5, 'MediaPipe palm detections scoring lower '
                                                'are dropped.', 0.0, 1.0)
    min_tracking_confidence: float = parameter(0.5, 'MediaPipe re-detects a tracked hand whose '
                                               'landmark score falls below this.', 0.0, 1.0)
    search_interval: int = parameter(
        3, 'MediaPipe: with one hand tracked, look for a second hand on every this-many-th '
        'frame only (its palm detector costs about as much as tracking a hand), and on every '
        'frame for a few frames after a hand was lost; 1: on every frame, as MediaPipe alone '
        'does.', 1, 1000)
    refine_iterations: int = parameter(0, 'L-BFGS steps refining the MANO fit of each MediaPipe '
                                       'hand after the closed-form start (0: none).', 0, 1000)
    ray_passes: int = parameter(
        2, "Passes turning a lifted MediaPipe hand's bones towards its landmarks' viewing rays "
        '(each kept only where it lowers the pixel error): more make the written joints land '
        'closer to the hand in the image, at 1-2 ms per pass and hand (the offline profile '
        'takes 8).', 0, 100)
    scene_cut_distance: float = parameter(
        0.3, "MediaPipe's hand tracking restarts when two consecutive images' hue-saturation "
        'histograms differ by more than this Bhattacharyya distance, also once the second is '
        'shifted onto the first and both are smoothed alike (a cut between scenes, not a fast '
        'turn or motion blur; 1: never).', 0.0, 1.0)

    def __post_init__(self) -> None:
        check_parameters(self, 'hands.')
