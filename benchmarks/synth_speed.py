"""Synthetic-data generation speed on one core: frames/s for rendering and for rendering + bag.

    python benchmarks/synth_speed.py [--frames 200] [--width 518 --height 378] [--json]

Pins the process to one CPU core (and one thread in torch and OpenCV), generates a sequence four
ways (render only; render only with still images, ``exposure_s: 0``, for the motion blur's cost;
render + raw-image MCAP bag; render + JPEG MCAP bag, zstd) and prints frames/s for each beside
the issue's 10 frames/s target.
"""

import argparse
from dataclasses import replace
import json
import os
from pathlib import Path
import tempfile
import time

import cv2
from infinihand_ros.synth.bag_sink import BagOptions
from infinihand_ros.synth.bag_sink import BagSink
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import torch

TARGET_FPS = 10.0
SEED = 1


def _pin_to_one_core() -> int:
    """Restrict the process to one core and one thread per library; return that core."""
    core = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {core})
    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    return core


def _time_run(config: SynthConfig, frames: int, bag_options: BagOptions | None) -> float:
    """Generate ``frames`` frames (and write them to a bag unless ``bag_options`` is None)."""
    start = time.perf_counter()
    sequence = SyntheticSequence(config, SEED, frames)
    if bag_options is None:
        for _ in sequence:
            pass
    else:
        with tempfile.TemporaryDirectory() as scratch:
            with BagSink(Path(scratch) / 'bag', bag_options) as sink:
                for frame in sequence:
                    sink.add(frame)
    return frames / (time.perf_counter() - start)


def main() -> None:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--frames', type=int, default=200)
    parser.add_argument('--width', type=int, default=518)
    parser.add_argument('--height', type=int, default=378)
    parser.add_argument('--json', action='store_true', help='print one JSON line')
    args = parser.parse_args()
    core = _pin_to_one_core()
    config = SynthConfig(width=args.width, height=args.height)
    _time_run(config, 5, None)  # warm-up (imports, allocations)
    results = {
        'render_fps': _time_run(config, args.frames, None),
        'render_still_fps': _time_run(replace(config, exposure_s=0.0), args.frames, None),
        'render_bag_raw_fps': _time_run(config, args.frames, BagOptions()),
        'render_bag_jpeg_zstd_fps': _time_run(
            config, args.frames, BagOptions(compress=True, image_codec='jpeg')),
    }
    if args.json:
        print(json.dumps({k: round(v, 2) for k, v in results.items()}))
        return
    print(f'synthetic generation, {args.width}x{args.height}, {args.frames} frames, '
          f'one core (cpu {core}), target {TARGET_FPS:.0f} frames/s')
    for name, fps in results.items():
        print(f'  {name:26s} {fps:7.1f} frames/s  ({fps / TARGET_FPS:.1f}x target)')


if __name__ == '__main__':
    main()
