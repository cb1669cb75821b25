"""A long stream through the engine: memory and per-frame time stay flat (slow).

3,000 small frames through a small model with a short trajectory cap, so the memory reaches its
steady state early: resident memory may not grow after the first thousand frames, and the last
thousand frames may not be slower than the first thousand (the old concatenating cache grew
4x in RSS and lost 40 % of its speed over such a stream).
"""

from dataclasses import replace
import os
from pathlib import Path
import time

from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.config import named_config_path
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest

FRAMES = 3000
SEGMENT = 1000
#: RSS may grow by at most this after the first segment (allocator noise, lazy pages).
RSS_SLACK_MB = 40.0
#: The last segment may be at most this much slower than the first (timing noise on CI).
TIME_RATIO_LIMIT = 1.3


def _rss_mb() -> float:
    pages = int(Path('/proc/self/statm').read_text().split()[1])
    return pages * os.sysconf('SC_PAGE_SIZE') / 2**20


@pytest.mark.slow
@pytest.mark.skipif(not Path('/proc/self/statm').exists(), reason='needs Linux /proc')
def test_three_thousand_frames_keep_memory_and_speed_flat() -> None:
    tiny = load_geometry_config(named_config_path('tiny'))
    geometry = replace(
        tiny, aggregator=replace(tiny.aggregator, image_height=84, image_width=112),
        memory=replace(tiny.memory, max_trajectory_frames=64))
    model = build_infinihand_model(geometry, load_hand_branch_config('tiny'), seed=0).eval()
    frames = list(SyntheticSequence(SynthConfig(width=112, height=84), seed=2, num_frames=30))
    rss, seconds = {}, np.zeros(FRAMES)
    with StreamingEngine(EngineConfig(), model) as engine:
        for index in range(FRAMES):
            frame = frames[index % len(frames)]
            start = time.perf_counter()
            engine.push(frame.rgb, index * 100_000_000, frame.intrinsics)
            seconds[index] = time.perf_counter() - start
            if (index + 1) % SEGMENT == 0:
                rss[index + 1] = _rss_mb()
        engine.flush()
    assert rss[FRAMES] - rss[SEGMENT] < RSS_SLACK_MB, rss
    first, last = np.median(seconds[:SEGMENT]), np.median(seconds[-SEGMENT:])
    assert last < TIME_RATIO_LIMIT * first, (first, last)
