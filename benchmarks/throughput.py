"""Engine throughput, latency and memory on a synthetic stream.

    python benchmarks/throughput.py [--config config/engine.yaml] [--frames 600] [--ba] [--json]

Renders a short synthetic sequence (518x378, both hands) once and replays it as a stream of
``--frames`` frames with increasing stamps. Runs the engine in per-frame mode (frames/s, push
latency p50/p95 after the anchors, resident memory after 300 frames and at the end) and in
windowed mode (frames/s); with ``--ba`` also per-frame mode with bundle adjustment off and on
(push latencies side by side; BA selections submitted, done, dropped, failed). The untrained
model's hand masks cover whole frames, which leaves BA nothing to track, so both BA runs ignore
hands (presence threshold 0.999): BA then does its full work (tracking and solving over the
model's depth and poses) while the stream runs. Prints one JSON line with ``--json``. Issue
targets for the tiny config on 2 cores: >= 10 frames/s per frame, p95 <= 150 ms, RSS at the end
<= RSS at 300 frames + 10 %.
"""

import argparse
from dataclasses import replace
import json
import os
from pathlib import Path
import time

from infinihand_ros.engine.config import load_engine_config
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np

DISTINCT_FRAMES = 40
RSS_CHECKPOINT = 300
FRAME_PERIOD_NS = 100_000_000
#: Hands ignored in the BA comparison (see the module docstring).
BA_PRESENCE_THRESHOLD = 0.999


def _rss_mb() -> float:
    """Return this process's resident set size in MiB (Linux)."""
    pages = int(Path('/proc/self/statm').read_text().split()[1])
    return pages * os.sysconf('SC_PAGE_SIZE') / 2**20


def _stream(frames: list, count: int):
    """Yield (image, stamp, intrinsics) for ``count`` frames, cycling the rendered ones."""
    for index in range(count):
        frame = frames[index % len(frames)]
        yield frame.rgb, index * FRAME_PERIOD_NS, frame.intrinsics


def _per_frame(engine: StreamingEngine, frames: list, count: int) -> dict:
    """Run per-frame mode; return frames/s, latencies and RSS figures."""
    latencies, rss_checkpoint, results = [], None, 0
    start = time.perf_counter()
    for index, (image, stamp, intrinsics) in enumerate(_stream(frames, count)):
        pushed = time.perf_counter()
        results += len(engine.push(image, stamp, intrinsics))
        if index >= engine.model.geometry.config.memory.anchor_frames:
            latencies.append(time.perf_counter() - pushed)
        if index + 1 == RSS_CHECKPOINT:
            rss_checkpoint = _rss_mb()
    results += len(engine.flush())
    elapsed = time.perf_counter() - start
    assert results == count, f'{results} results for {count} frames'
    return {'fps_per_frame': count / elapsed,
            'latency_p50_ms': 1e3 * float(np.percentile(latencies, 50)),
            'latency_p95_ms': 1e3 * float(np.percentile(latencies, 95)),
            'rss_mb_300': rss_checkpoint, 'rss_mb_end': _rss_mb()}


def _windowed(engine: StreamingEngine, frames: list, count: int) -> float:
    """Run windowed mode; return frames/s."""
    results = 0
    start = time.perf_counter()
    for image, stamp, intrinsics in _stream(frames, count):
        results += len(engine.push(image, stamp, intrinsics))
    results += len(engine.flush())
    assert results == count, f'{results} results for {count} frames'
    return count / (time.perf_counter() - start)


def main() -> None:
    """Run both modes and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--config', type=Path, default=None, help='engine YAML')
    parser.add_argument('--frames', type=int, default=600)
    parser.add_argument('--ba', action='store_true', help='also run with bundle adjustment on')
    parser.add_argument('--json', action='store_true', help='print one JSON line')
    args = parser.parse_args()
    config = load_engine_config(args.config)
    frames = list(SyntheticSequence(SynthConfig(), seed=1, num_frames=DISTINCT_FRAMES))
    model = build_model(config)
    with StreamingEngine(replace(config, mode='per_frame'), model) as engine:
        figures = _per_frame(engine, frames, args.frames)
    with StreamingEngine(replace(config, mode='windowed'), model) as engine:
        figures['fps_windowed'] = _windowed(engine, frames, args.frames)
    if args.ba:
        for name, enabled in (('ba_off', False), ('ba_on', True)):
            ba_config = replace(config, mode='per_frame', bundle_adjustment=enabled,
                                presence_threshold=BA_PRESENCE_THRESHOLD)
            with StreamingEngine(ba_config, model) as engine:
                run = _per_frame(engine, frames, args.frames)
                if enabled:
                    figures.update({f'ba_{key}': value
                                    for key, value in engine.ba_statistics.items()})
            figures[f'latency_p50_ms_{name}'] = run['latency_p50_ms']
            figures[f'latency_p95_ms_{name}'] = run['latency_p95_ms']
    rounded = {key: (None if value is None else round(value, 1)) for key, value in figures.items()}
    if args.json:
        print(json.dumps(rounded))
        return
    print(f'engine {config.geometry}/{config.hand_branch} on {config.device}, {args.frames} '
          'frames of 518x378:')
    for key, value in rounded.items():
        print(f'  {key:16s} {value}')


if __name__ == '__main__':
    main()
