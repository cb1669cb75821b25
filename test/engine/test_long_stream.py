"""A long stream through the engine: memory stays flat (slow).

500 small frames through a small model with short caps (trajectory 32 frames, pose track 128
frames, scale history 25 ratios), so every bounded store is full after the first 200 frames:
resident memory may not grow after them (the old concatenating cache grew 4x in RSS over such a
stream). Thousands of frames, and speed over them, are a benchmark's
figures, not a test's (``benchmarks/throughput.py`` prints the first and last frames' rates): on
the shared 2-core CPU the median time per frame of 500-frame blocks wanders by 40 % with no trend.
"""

from dataclasses import replace
import os
from pathlib import Path

from engine_configs import seeded_tiny
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.config import named_config_path
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import pytest

FRAMES = 500
WARM_UP = 200
#: RSS may grow by at most this after the warm-up (allocator noise, lazy pages).
RSS_SLACK_MB = 40.0


def _rss_mb() -> float:
    pages = int(Path('/proc/self/statm').read_text().split()[1])
    return pages * os.sysconf('SC_PAGE_SIZE') / 2**20


@pytest.mark.slow
@pytest.mark.skipif(not Path('/proc/self/statm').exists(), reason='needs Linux /proc')
def test_long_stream_keeps_memory_flat() -> None:
    tiny = load_geometry_config(named_config_path('tiny'))
    geometry = replace(
        tiny, aggregator=replace(tiny.aggregator, image_height=84, image_width=112),
        memory=replace(tiny.memory, max_trajectory_frames=32))
    model = build_infinihand_model(geometry, load_hand_branch_config('tiny'), seed=0).eval()
    frames = list(SyntheticSequence(SynthConfig(width=112, height=84), seed=2, num_frames=30))
    rss = {}
    config = seeded_tiny()
    config = replace(config, pose_track=replace(config.pose_track, capacity=128),
                     metric_scale=replace(config.metric_scale, history=25))
    with StreamingEngine(config, model) as engine:
        for index in range(FRAMES):
            frame = frames[index % len(frames)]
            engine.push(frame.rgb, index * 100_000_000, frame.intrinsics)
            if index + 1 in (WARM_UP, FRAMES):
                rss[index + 1] = _rss_mb()
        engine.flush()
    assert rss[FRAMES] - rss[WARM_UP] < RSS_SLACK_MB, rss
