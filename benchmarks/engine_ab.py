"""Engine variants side by side on the sample bag: speed ratios and output differences.

    python benchmarks/engine_ab.py [--variants fp32/2/per_frame auto/2/per_frame ...]
        [--rounds 3] [--frames 150] [--config config/engine.yaml] [--json]

A variant is ``precision/threads/mode``: ``engine.cpu_precision`` (fp32 | auto), torch
intra-op threads, ``engine.mode`` (per_frame | windowed). Each round runs every variant once, in
turn, on the same frames (the sample bag ``data/sample_bag``, cycled to ``--frames``; one model
shared by all), so the machine's load (printed: the 1-minute load average before and after)
hits every variant alike; the figures are the median over rounds of frames/s, push latency p95
after the anchors and the ratio of frames/s to the first variant within each round. Each
variant's outputs of its first round are compared with the first variant's (the reference):
camera positions (model units x metric scale, as published) and rotations, the metric scale,
and the world-frame joints of the hands both found, with max and mean differences, and the
frames whose detected sides differ. Figures only; nothing is asserted.
"""

import argparse
from dataclasses import dataclass
from dataclasses import replace
import json
import os
from pathlib import Path
import statistics
import time

from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.engine.config import CPU_PRECISIONS
from infinihand_ros.engine.config import MODES
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.settings import load_engine_config
from infinihand_ros.engine.streaming_engine import StreamingEngine
import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_BAG = ROOT / 'data' / 'sample_bag'
MM_PER_M = 1e3
MS_PER_S = 1e3


@dataclass(frozen=True)
class Variant:
    """One engine setting: CPU precision, torch threads, mode."""

    precision: str
    threads: int
    mode: str

    @property
    def name(self) -> str:
        """Return the variant as written on the command line."""
        return f'{self.precision}/{self.threads}/{self.mode}'


def _variant(text: str) -> Variant:
    """Parse ``precision/threads/mode``."""
    try:
        precision, threads, mode = text.split('/')
        variant = Variant(precision, int(threads), mode)
    except ValueError:
        raise argparse.ArgumentTypeError(f'variant {text!r}: expected precision/threads/mode, '
                                         'e.g. auto/1/per_frame') from None
    if precision not in CPU_PRECISIONS or mode not in MODES or variant.threads < 1:
        raise argparse.ArgumentTypeError(f'variant {text!r}: precision one of '
                                         f'{list(CPU_PRECISIONS)}, threads >= 1, mode one of '
                                         f'{list(MODES)}')
    return variant


def _run(engine: StreamingEngine, frames: list, count: int) -> tuple[list[FrameResult], dict]:
    """Stream ``count`` frames; return the results, frames/s and push latency p95."""
    anchors = engine.model.geometry.config.memory.anchor_frames
    results, latencies = [], []
    start = time.perf_counter()
    for index in range(count):
        frame = frames[index % len(frames)]
        pushed = time.perf_counter()
        results += engine.push(frame.rgb, index * 100_000_000, frame.intrinsics)
        if index >= anchors:
            latencies.append(time.perf_counter() - pushed)
    results += engine.flush()
    elapsed = time.perf_counter() - start
    return results, {'fps': count / elapsed,
                     'latency_p95_ms': MS_PER_S * float(np.percentile(latencies, 95))}


def _rotation_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Return the angle of the rotation between two rotation matrices, degrees."""
    cosine = (np.trace(a.T @ b) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))


def differences(reference: list[FrameResult], other: list[FrameResult]) -> dict:
    """Return max/mean differences of poses, scale and joints between two result streams."""
    position, rotation, scale, joints, sides = [], [], [], [], 0
    for a, b in zip(reference, other, strict=True):
        position.append(float(np.linalg.norm(a.camera_pose.translation
                                             - b.camera_pose.translation)))
        rotation.append(_rotation_deg(a.camera_pose.rotation, b.camera_pose.rotation))
        scale.append(abs(b.metric_scale / a.metric_scale - 1.0))
        hands_a = {hand.side: hand for hand in a.hands}
        hands_b = {hand.side: hand for hand in b.hands}
        sides += hands_a.keys() != hands_b.keys()
        for side in hands_a.keys() & hands_b.keys():
            joints.append(float(np.linalg.norm(hands_a[side].joints_world
                                               - hands_b[side].joints_world, axis=-1).max()))
    path = np.array([result.camera_pose.translation for result in reference])
    figures = {'camera_path_extent': float(np.ptp(path, axis=0).max()),
               'frames_with_other_sides': sides, 'hands_compared': len(joints)}
    for name, values, unit in (('camera_position', position, 1.0),
                               ('camera_rotation_deg', rotation, 1.0),
                               ('metric_scale_relative', scale, 1.0),
                               ('joints_world_mm', joints, MM_PER_M)):
        if values:
            figures[f'{name}_max'] = unit * max(values)
            figures[f'{name}_mean'] = unit * float(np.mean(values))
    return figures


def main() -> None:
    """Run the rounds and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--variants', nargs='+', type=_variant,
                        default=[_variant('fp32/2/per_frame'), _variant('auto/2/per_frame'),
                                 _variant('auto/1/per_frame'), _variant('auto/1/windowed')])
    parser.add_argument('--rounds', type=int, default=3)
    parser.add_argument('--frames', type=int, default=150, help='frames per run (>= 3)')
    parser.add_argument('--config', type=Path, default=None, help='engine YAML')
    parser.add_argument('--json', action='store_true', help='print one JSON line')
    args = parser.parse_args()
    config = load_engine_config(args.config)
    model = build_model(config)
    frames = list(read_camera_frames(SAMPLE_BAG))
    load_before = os.getloadavg()[0]
    runs: dict[str, list[dict]] = {variant.name: [] for variant in args.variants}
    outputs: dict[str, list[FrameResult]] = {}
    for _ in range(args.rounds):
        for variant in args.variants:
            torch.set_num_threads(variant.threads)
            engine_config = replace(config, cpu_precision=variant.precision, mode=variant.mode)
            with StreamingEngine(engine_config, model) as engine:
                results, figures = _run(engine, frames, args.frames)
            outputs.setdefault(variant.name, results)
            runs[variant.name].append(figures)
    reference = args.variants[0].name
    summary = {'load_1min_before': load_before, 'load_1min_after': os.getloadavg()[0],
               'frames': args.frames, 'rounds': args.rounds, 'variants': {}}
    for variant in args.variants:
        name = variant.name
        ratios = [run['fps'] / base['fps'] for run, base in zip(runs[name], runs[reference])]
        summary['variants'][name] = {
            'fps': statistics.median(run['fps'] for run in runs[name]),
            'fps_per_round': [run['fps'] for run in runs[name]],
            'latency_p95_ms': statistics.median(run['latency_p95_ms'] for run in runs[name]),
            'fps_ratio_to_reference': statistics.median(ratios),
            'outputs_vs_reference': differences(outputs[reference], outputs[name])}
    if args.json:
        print(json.dumps(summary))
        return
    print(f'{args.frames} sample-bag frames x {args.rounds} rounds, reference {reference}; '
          f'load (1 min) {summary["load_1min_before"]:.1f} before, '
          f'{summary["load_1min_after"]:.1f} after')
    for name, figures in summary['variants'].items():
        rounds = ' '.join(f'{fps:.1f}' for fps in figures['fps_per_round'])
        print(f'  {name:20s} {figures["fps"]:6.1f} frames/s (rounds {rounds})  x'
              f'{figures["fps_ratio_to_reference"]:.2f}  p95 {figures["latency_p95_ms"]:.0f} ms')
        print('      vs reference: ' + ', '.join(
            f'{key} {value:.3g}' for key, value in figures['outputs_vs_reference'].items()))


if __name__ == '__main__':
    main()
