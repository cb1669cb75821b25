"""GPU readiness in one run: the paper-size engine streaming, converted weights, a training step.

    python benchmarks/gpu_check.py [--size paper] [--device cuda] [--frames 1000]
        [--out gpu_check.json]

Meant for a machine with one large NVIDIA GPU (well under 8 minutes there); the test suite runs
it with ``--size tiny --device cpu`` and a few frames. Writes one JSON file (and prints it):

1. ``stream``: the ``--size`` model (``config/model_<size>.yaml`` and the hand branch of that
   name) with seeded weights streams ``--frames`` synthetic frames (518 x 378, cycled from 40
   rendered ones, stamped at 30 Hz) in per-frame and in windowed mode, and with the ``live``
   profile (MediaPipe hands, the geometry interval paced to the 30 Hz stamps from measured
   cost: the interval it chose and the costs are printed); frames/s, push latency p95 after
   the anchors and the peak memory (CUDA: ``max_memory_allocated``; CPU: the process's peak
   RSS).
   bf16 as the engine runs it: the aggregator under autocast (``autocast_bf16``) on CUDA,
   ``engine.cpu_precision: auto`` on the CPU.
2. ``converted``: the same in per-frame mode with geometry weights in LingBot-Map's layout (the
   seeded model's aggregator / camera head / depth head tensors saved as
   ``{"model": {"module." + key}}``) converted by ``model/io/convert_lingbot_map.py`` and loaded
   through ``engine.model.geometry_weights``.
3. ``train_step``: one Stage II step (``config/train_<size>_stage2.yaml``, batch 1, on one
   synthetic sequence as long as one clip): the trainer's seconds per step, the whole run's
   (model building included) and the data writing's seconds apart, and the peak memory.
"""

import argparse
from dataclasses import replace
import json
import os
from pathlib import Path
import platform
import resource
import tempfile
import time

from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.settings import build_engine_config
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.model.config import named_config_path
from infinihand_ros.model.io.convert_lingbot_map import convert_checkpoint
from infinihand_ros.synth.batch import write_sequence
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
from infinihand_ros.train.train_config import load_train_config
from infinihand_ros.train.train_config import named_train_config_path
from infinihand_ros.train.trainer import train
import numpy as np
import torch

DISTINCT_FRAMES = 40
FRAME_PERIOD_NS = 33_333_333
UPSTREAM_PREFIXES = ('aggregator.', 'camera_head.', 'depth_head.')
MS_PER_S = 1e3
MIB = 2**20
KIB_PER_MIB = 1024


def _reset_peak(device: torch.device) -> None:
    """Start a new peak-memory measurement (CUDA only; the CPU's peak RSS only grows)."""
    if device.type == 'cuda':
        torch.cuda.synchronize(device)
        torch.cuda.reset_peak_memory_stats(device)


def _peak_mib(device: torch.device) -> float:
    """Return the peak memory since ``_reset_peak``: CUDA allocated, or the process's RSS."""
    if device.type == 'cuda':
        torch.cuda.synchronize(device)
        return torch.cuda.max_memory_allocated(device) / MIB
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / KIB_PER_MIB


def _stream(engine: StreamingEngine, frames: list, count: int, device: torch.device) -> dict:
    """Stream ``count`` frames; return frames/s, latency p95 and the peak memory."""
    anchors = engine.model.geometry.config.memory.anchor_frames
    _reset_peak(device)
    latencies, results = [], 0
    start = time.perf_counter()
    for index in range(count):
        frame = frames[index % len(frames)]
        pushed = time.perf_counter()
        results += len(engine.push(frame.rgb, index * FRAME_PERIOD_NS, frame.intrinsics))
        if index >= anchors:
            latencies.append(time.perf_counter() - pushed)
    results += len(engine.flush())
    elapsed = time.perf_counter() - start
    if results != count:
        raise RuntimeError(f'{results} results for {count} frames')
    return {'frames': count, 'fps': count / elapsed,
            'latency_p95_ms': MS_PER_S * float(np.percentile(latencies, 95)),
            'peak_memory_mib': _peak_mib(device)}


def _lingbot_map_checkpoint(model: torch.nn.Module, folder: Path) -> Path:
    """Save the geometry branch's upstream tensors in LingBot-Map's layout; return the file."""
    state = {'module.' + key: value.detach().float().cpu()
             for key, value in model.geometry.state_dict().items()
             if key.startswith(UPSTREAM_PREFIXES)}
    path = folder / 'lingbot_map.pt'
    torch.save({'model': state}, path)
    return path


def _train_step(size: str, device: str, folder: Path) -> dict:
    """Run one Stage II step on one synthetic sequence; return its time and peak memory."""
    config = load_train_config(named_train_config_path(f'{size}_stage2'))
    clip = config.clip
    length = clip.anchor_frames + clip.num_windows * clip.window_frames * clip.frame_stride
    start = time.perf_counter()
    write_sequence(SynthConfig(), seed=1, frames=length, out=folder / 'sequence')
    config = replace(config, data=replace(config.data, sequences=(str(folder / 'sequence'
                                                                      / 'samples'),),
                                          num_workers=0),
                     batch_size=1, steps=1, device=device, checkpoint_every=10**9)
    prepared = time.perf_counter()
    torch_device = torch.device(device)
    _reset_peak(torch_device)
    result = train(config, folder / 'run', progress=False)
    done = time.perf_counter()
    return {'sequence_frames': length, 'data_seconds': prepared - start,
            'run_seconds': done - prepared, 'step_seconds': result.seconds_per_step,
            'steps': result.last_step - result.first_step, 'loss': result.losses[-1],
            'peak_memory_mib': _peak_mib(torch_device)}


def run_check(size: str, device: str, frames: int, folder: Path) -> dict:
    """Run the three checks; return the figures (see the module docstring)."""
    torch_device = torch.device(device)
    base = build_engine_config('synthetic')
    model_selection = replace(base.model, geometry=size, hand_branch=size, checkpoint=None)
    config = replace(base, device=device, model=model_selection, cpu_precision='auto')
    rendered = list(SyntheticSequence(SynthConfig(), seed=1, num_frames=DISTINCT_FRAMES))
    figures: dict = {
        'size': size, 'device': device, 'torch': torch.__version__,
        'machine': (torch.cuda.get_device_name(torch_device) if torch_device.type == 'cuda'
                    else platform.processor() or platform.machine()),
        'geometry_config': str(named_config_path(size)), 'stream': {}}
    model = build_model(config)
    figures['parameters'] = sum(parameter.numel() for parameter in model.parameters())
    for mode in ('per_frame', 'windowed'):
        with StreamingEngine(replace(config, mode=mode), model) as engine:
            figures['stream'][mode] = _stream(engine, rendered, frames, torch_device)
    live = build_engine_config('live')  # MediaPipe hands, the geometry interval paced
    live = replace(live, device=device, model=model_selection, cpu_precision='auto')
    with StreamingEngine(live, model) as engine:
        figures['stream']['live'] = {**_stream(engine, rendered, frames, torch_device),
                                     'pacing': engine.statistics['pacing']}
    checkpoint = _lingbot_map_checkpoint(model, folder)
    del model
    converted_dir = folder / 'converted'
    _, report = convert_checkpoint('lingbot-map', checkpoint, named_config_path(size),
                                   converted_dir)
    converted = replace(config, model=replace(model_selection, geometry_weights=str(
        converted_dir)))
    with StreamingEngine(converted) as engine:
        figures['converted'] = {'matched_tensors': report.matched,
                                **_stream(engine, rendered, frames, torch_device)}
    figures['train_step'] = _train_step(size, device, folder)
    return figures


def main() -> None:
    """Run the checks and write the JSON file."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--size', default='paper', help='model size: paper | tiny | tiny_336')
    parser.add_argument('--device', default='cuda', help='cuda | cuda:N | cpu')
    parser.add_argument('--frames', type=int, default=1000, help='frames per stream (>= 3)')
    parser.add_argument('--out', type=Path, default=Path('gpu_check.json'))
    args = parser.parse_args()
    if args.frames < 3:
        parser.error(f'--frames must be at least 3, got {args.frames}')
    with tempfile.TemporaryDirectory(prefix='gpu_check_') as folder:
        figures = run_check(args.size, args.device, args.frames, Path(folder))
    figures['load_1min'] = os.getloadavg()[0]
    text = json.dumps(figures, indent=1)
    args.out.write_text(text + '\n', encoding='utf-8')
    print(text)


if __name__ == '__main__':
    main()
