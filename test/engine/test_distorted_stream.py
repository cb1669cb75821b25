"""A distorted stream with its lens scores like its pinhole twin (the engine rectifies it)."""

from dataclasses import replace

from infinihand_ros.engine.settings import build_engine_config
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest

SYNTH = SynthConfig(width=320, height=240)
LENS = 'plumb_bob:-0.25,0.08,0,0,0'
NUM_FRAMES = 6


@pytest.fixture(scope='module')
def engine() -> StreamingEngine:
    """Yield an engine with the bundled model (trained on synthetic images), as in eval."""
    with StreamingEngine(build_engine_config('synthetic')) as engine:
        yield engine


def _camera_error_mm(engine: StreamingEngine, frames: list) -> tuple[float, list]:
    """Run the frames; return the mean camera-frame joint error (mm) and the results."""
    results = []
    for frame in frames:
        results += engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics)
    results += engine.flush()
    engine.reset()
    errors = [np.linalg.norm(result.hand(hand.side).joints_cam - hand.joints_cam, axis=1).mean()
              for frame, result in zip(frames, results) for hand in frame.hands
              if hand.visible and result.hand(hand.side) is not None]
    assert len(errors) >= NUM_FRAMES  # hands were found: the comparison means something
    return 1000.0 * float(np.mean(errors)), results


def test_distorted_stream_scores_like_its_pinhole_twin(engine: StreamingEngine) -> None:
    """Same seed, same scene: with the lens given, the hands are as good as without a lens."""
    pinhole = list(SyntheticSequence(SYNTH, seed=3, num_frames=NUM_FRAMES))
    distorted = list(SyntheticSequence(replace(SYNTH, distortion=LENS), seed=3,
                                       num_frames=NUM_FRAMES))
    assert np.abs(distorted[0].rgb.astype(int) - pinhole[0].rgb).mean() > 10  # a strong lens
    base, _ = _camera_error_mm(engine, pinhole)
    error, results = _camera_error_mm(engine, distorted)
    assert results[0].intrinsics.distortion_model == 'plumb_bob'  # the outputs carry the lens
    assert error < 1.15 * base + 2.0, (error, base)
