"""Engine throughput, latency and memory on a long synthetic stream.

    python benchmarks/throughput.py [--config config/engine.yaml] [--frames 3000] [--ba] [--json]
        [--modes per_frame windowed] [--threads N] [--cpu-precision auto|fp32]

Renders a short synthetic sequence (518x378, both hands) once and replays it as a stream of
``--frames`` frames with increasing stamps (at least 3). In each mode it prints frames/s over
the whole stream and over its first and last thousand frames (or tenth, for short streams),
push latency p50/p95 after the anchors (per-frame mode), and the resident memory (RSS) at frames
300, 1,000, 3,000 and 10,000 (those the stream reaches) and at the end. With ``--ba`` it also
runs per-frame mode with bundle adjustment off and on (push latencies side by side; BA
selections submitted, done, dropped, failed). The untrained model's hand masks cover whole
frames, which leaves BA nothing to track, so both BA runs ignore hands (presence threshold
0.999): BA then does its full work (tracking and solving over the model's depth and poses) while
the stream runs. ``--threads`` sets torch's intra-op threads (default: torch's, one per core) and
``--cpu-precision`` overrides ``engine.cpu_precision``. The 1-minute load average before and
after is printed with the figures (other processes on the machine slow every figure). Prints one
JSON line with ``--json``.
"""

import argparse
from dataclasses import replace
import json
import os
from pathlib import Path
import time

from infinihand_ros.ba.config import load_ba_config
from infinihand_ros.engine.config import CPU_PRECISIONS
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.settings import load_engine_config
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import torch

DISTINCT_FRAMES = 40
RSS_CHECKPOINTS = (300, 1000, 3000, 10000)
MIN_FRAMES = 3
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


def _run(engine: StreamingEngine, frames: list, count: int, prefix: str) -> dict:
    """Stream ``count`` frames; return frames/s (whole, first and last segment), latency, RSS."""
    segment = min(1000, max(1, count // 10))
    latencies, rss, results, done_at = [], {}, 0, []
    anchors = engine.model.geometry.config.memory.anchor_frames
    start = time.perf_counter()
    for index, (image, stamp, intrinsics) in enumerate(_stream(frames, count)):
        pushed = time.perf_counter()
        results += len(engine.push(image, stamp, intrinsics))
        done_at.append(time.perf_counter())
        if index >= anchors:
            latencies.append(done_at[-1] - pushed)
        if index + 1 in RSS_CHECKPOINTS:
            rss[f'{prefix}_rss_mb_{index + 1}'] = _rss_mb()
    results += len(engine.flush())
    elapsed = time.perf_counter() - start
    if results != count:
        raise RuntimeError(f'{results} results for {count} frames')
    first = segment / (done_at[segment - 1] - start)
    last = segment / (done_at[-1] - done_at[-segment - 1]) if count > segment else first
    return {f'{prefix}_fps': count / elapsed, f'{prefix}_fps_first_{segment}': first,
            f'{prefix}_fps_last_{segment}': last,
            f'{prefix}_latency_p50_ms': 1e3 * float(np.percentile(latencies, 50)),
            f'{prefix}_latency_p95_ms': 1e3 * float(np.percentile(latencies, 95)),
            **rss, f'{prefix}_rss_mb_end': _rss_mb()}


def _frame_count(text: str) -> int:
    """Parse ``--frames``: an integer of at least MIN_FRAMES."""
    count = int(text)
    if count < MIN_FRAMES:
        raise argparse.ArgumentTypeError(f'--frames must be at least {MIN_FRAMES}, got {count}')
    return count


def main() -> None:
    """Run the modes and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--config', type=Path, default=None, help='engine YAML')
    parser.add_argument('--frames', type=_frame_count, default=3000,
                        help=f'stream length (>= {MIN_FRAMES})')
    parser.add_argument('--modes', nargs='+', choices=('per_frame', 'windowed'),
                        default=['per_frame', 'windowed'])
    parser.add_argument('--ba', action='store_true', help='also run with bundle adjustment on')
    parser.add_argument('--threads', type=int, default=None,
                        help="torch intra-op threads (default: torch's)")
    parser.add_argument('--cpu-precision', choices=CPU_PRECISIONS, default=None,
                        help='override engine.cpu_precision')
    parser.add_argument('--json', action='store_true', help='print one JSON line')
    args = parser.parse_args()
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    config = load_engine_config(args.config)
    if args.cpu_precision is not None:
        config = replace(config, cpu_precision=args.cpu_precision)
    load_before = os.getloadavg()[0]
    frames = list(SyntheticSequence(SynthConfig(), seed=1, num_frames=DISTINCT_FRAMES))
    model = build_model(config)
    figures = {}
    for mode in args.modes:
        with StreamingEngine(replace(config, mode=mode), model) as engine:
            figures.update(_run(engine, frames, args.frames, mode))
    if args.ba:
        for name, enabled in (('ba_off', False), ('ba_on', True)):
            ba_config = replace(
                config, mode='per_frame',
                bundle_adjustment=load_ba_config() if enabled else None,
                detection=replace(config.detection, presence_threshold=BA_PRESENCE_THRESHOLD))
            with StreamingEngine(ba_config, model) as engine:
                run = _run(engine, frames, args.frames, name)
                if enabled:
                    figures.update({f'ba_{key}': value
                                    for key, value in engine.statistics['ba'].items()})
            figures.update({key: value for key, value in run.items() if 'latency' in key})
    figures.update(threads=torch.get_num_threads(), cpu_precision=config.cpu_precision,
                   load_1min_before=load_before, load_1min_after=os.getloadavg()[0])
    rounded = {key: (round(value, 1) if isinstance(value, float) else value)
               for key, value in figures.items()}
    if args.json:
        print(json.dumps(rounded))
        return
    print(f'engine {config.model.geometry}/{config.model.hand_branch} on {config.device}, '
          f'{args.frames} frames of 518x378:')
    for key, value in rounded.items():
        print(f'  {key:28s} {value}')


if __name__ == '__main__':
    main()
