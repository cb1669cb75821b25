"""Real pixels for tests: the shared hand photos.

``infinihand_ros.synth.photo_streams`` turns one into a video with exact cameras.

``../shared/data/real_hands_stills`` (30 real hand photos, 640x480, fx = fy = 500) is read
from outside the repository; tests that use it skip when it is absent (``require_stills``).
"""

from pathlib import Path

from infinihand_ros.bag.camera_stream import read_camera_frames
import pytest

STILLS = Path(__file__).resolve().parents[2] / 'shared' / 'data' / 'real_hands_stills'


def require_stills() -> list:
    """Return the stills' camera frames, or skip the test when the shared data is absent."""
    if not STILLS.is_dir():
        pytest.skip(f'real hand stills not found at {STILLS} (shared data absent)')
    return list(read_camera_frames(STILLS))
