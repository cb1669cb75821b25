"""Geometry-branch speed: milliseconds per frame in per-frame streaming (and windows of frames).

    python benchmarks/geometry_speed.py [--config config/model_tiny.yaml] [--frames 30]
        [--window 16] [--threads 1] [--device cpu] [--json]

Builds the configured model with random weights (seeded), streams the anchor frames in one call
and then ``--frames`` frames one by one (all keyframes), and prints the median and mean time per
frame; then the same frames in calls of ``--window`` frames. On the CPU the process is pinned to
one core and ``--threads`` torch threads.
"""

import argparse
import json
import os
import statistics
import time

from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.config import named_config_path
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.geometry_stream import GeometryStream
import torch

SEED = 1


def _pin(threads: int) -> int:
    """Restrict the process to one core and ``threads`` torch threads; return that core."""
    core = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {core})
    torch.set_num_threads(threads)
    return core


def _synchronize(device: torch.device) -> None:
    if device.type == 'cuda':
        torch.cuda.synchronize(device)


def _stream_times(stream: GeometryStream, frames: torch.Tensor, anchors: int, window: int
                  ) -> list[float]:
    """Return seconds per frame for calls of ``window`` frames after the anchor call."""
    stream.reset()
    stream.step(frames[:, :anchors])
    times = []
    for start in range(anchors, frames.shape[1], window):
        chunk = frames[:, start:start + window]
        _synchronize(frames.device)
        began = time.perf_counter()
        stream.step(chunk)
        _synchronize(frames.device)
        times.append((time.perf_counter() - began) / chunk.shape[1])
    return times


def main() -> None:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--config', default=str(named_config_path('tiny')))
    parser.add_argument('--frames', type=int, default=30)
    parser.add_argument('--window', type=int, default=16)
    parser.add_argument('--threads', type=int, default=1)
    parser.add_argument('--device', default='cpu')
    parser.add_argument('--json', action='store_true', help='print one JSON line')
    args = parser.parse_args()
    device = torch.device(args.device)
    core = _pin(args.threads) if device.type == 'cpu' else None
    config = load_geometry_config(args.config)
    torch.manual_seed(SEED)
    model = GeometryModel(config).to(device).eval()
    stream = GeometryStream(model)
    anchors = config.memory.anchor_frames
    height, width = config.aggregator.image_height, config.aggregator.image_width
    frames = torch.rand(1, anchors + args.frames, 3, height, width,
                        generator=torch.Generator().manual_seed(SEED)).to(device)
    with torch.inference_mode():
        _stream_times(stream, frames[:, :anchors + 2], anchors, 1)  # warm-up
        per_frame = _stream_times(stream, frames, anchors, 1)
        windowed = _stream_times(stream, frames, anchors, args.window)
    results = {
        'config': args.config, 'device': str(device), 'threads': args.threads,
        'frames': args.frames, 'per_frame_ms_median': 1e3 * statistics.median(per_frame),
        'per_frame_ms_mean': 1e3 * statistics.mean(per_frame),
        'windowed_ms_per_frame': 1e3 * statistics.mean(windowed), 'window': args.window,
    }
    if args.json:
        print(json.dumps({k: round(v, 2) if isinstance(v, float) else v
                          for k, v in results.items()}))
        return
    where = f'cpu {core}, {args.threads} thread(s)' if core is not None else str(device)
    print(f'geometry branch {args.config}, {width}x{height}, {args.frames} frames, {where}')
    print(f'  per-frame streaming  {results["per_frame_ms_median"]:8.1f} ms/frame (median), '
          f'{results["per_frame_ms_mean"]:.1f} mean')
    print(f'  windows of {args.window:<3d}       {results["windowed_ms_per_frame"]:8.1f} ms/frame')


if __name__ == '__main__':
    main()
