"""Fixtures of the hand-branch tests: one small synthetic frame with both hands visible."""

from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
from infinihand_ros.synth.sequence import SynthFrame
import pytest

#: A seed whose first frame shows both hands fully at 224 x 168 (the tiny model's input size).
FRAME_SEED = 3


@pytest.fixture(scope='session')
def synth_frame() -> SynthFrame:
    """Return frame 0 of a small seeded synthetic sequence (exact ground truth)."""
    frame = SyntheticSequence(SynthConfig(width=224, height=168), seed=FRAME_SEED,
                              num_frames=1).frame(0)
    assert all(hand.visible for hand in frame.hands), 'fixture frame must show both hands'
    return frame
