"""MediaPipe Hands on real hand photos (``../shared/data/real_hands_stills``, else skipped)."""

from pathlib import Path

from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.corpus.pseudo_labels import place_hand
from infinihand_ros.engine.hands.mediapipe_keypoints import MediaPipeConfig
import numpy as np
import pytest

STILLS = Path(__file__).resolve().parents[3] / 'shared' / 'data' / 'real_hands_stills'


@pytest.fixture(scope='module')
def detections() -> list:
    """Return each of the 30 photos with the hands MediaPipe finds in it."""
    if not STILLS.is_dir():
        pytest.skip(f'real hand photos not found at {STILLS}')
    mediapipe_source = pytest.importorskip('infinihand_ros.engine.hands.mediapipe_keypoints')
    frames = list(read_camera_frames(STILLS))
    with mediapipe_source.MediaPipeKeypointSource() as source:
        return [(frame, source.detect(frame.rgb, i)) for i, frame in enumerate(frames)]


def test_finds_one_hand_in_most_real_photos(detections: list) -> None:
    """In at least 24 of the 30 photos a confident hand lies inside the image."""
    found = [(frame, max(hands, key=lambda h: h.confidence))
             for frame, hands in detections if hands]
    assert len(found) >= 24
    for frame, hand in found:
        assert hand.side in (0, 1) and hand.confidence > 0.5
        height, width = frame.rgb.shape[:2]
        assert np.all((hand.joints_2d >= -5) & (hand.joints_2d <= [width + 5, height + 5]))
        assert hand.joints_metric.shape == (21, 3)


def test_pnp_puts_real_hands_at_arm_length(detections: list) -> None:
    """Place the metric landmarks by PnP: 0.1-4 m deep, small residual.

    (fx = 500 px is not calibrated, so depths are only plausible, not checked.)
    """
    for frame, hands in detections:
        intr = frame.intrinsics
        K = np.array([[intr.fx, 0, intr.cx], [0, intr.fy, intr.cy], [0, 0, 1.0]])
        for hand in hands:
            joints, error_px = place_hand(hand, K)
            assert 0.1 < joints[0, 2] < 4.0
            assert error_px < 10.0


def test_config_rejects_unknown_complexity() -> None:
    """A model complexity other than 0 or 1 is a ConfigError naming the value."""
    with pytest.raises(ConfigError, match='model_complexity must be 0 or 1, got 2'):
        MediaPipeConfig(model_complexity=2)
