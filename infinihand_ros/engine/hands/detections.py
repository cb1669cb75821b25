"""What a hand source found in one source image, handed from its detection to its lifting."""

from dataclasses import dataclass

from infinihand_ros.engine.hands.keypoints import Detection2D


@dataclass(frozen=True)
class FrameDetections:
    """One image's detections (``HandSource.detect``), read by ``HandSource.camera_hands``.

    Attributes:
        hands: the hands found (at most two), in the source image's pixels.
        scene_cut: the image starts a new scene (the source restarted its tracking there):
            nothing seen before it carries over (warm starts, hand identity, smoothing).

    """

    hands: tuple[Detection2D, ...] = ()
    scene_cut: bool = False
