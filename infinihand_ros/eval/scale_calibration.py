"""Measure a checkpoint's hand-depth correction of the metric scale on sequences with true depth.

    python -m infinihand_ros.eval.scale_calibration --sequences runs/synth/seed_* \
        [--checkpoint CK] [--every 5] [--write DIR]

The engine takes the metric scale from hands: a hand's metric depth over the depth head's depth
at its joints. A depth head that blurs small hands into the background puts them too far
relative to the rest of the scene, and the scale (so every camera translation) comes out short
by that factor. Per sampled frame this compares the scene's true scale (true depth over the
engine's depth, median over the pixels off the hands) with the hands' own ratio (the engine's
samples, the same median over joints); the correction is the median over sequences of each
sequence's median. Use sequences the model was trained on, never the held-out ones. ``--write``
puts it into ``DIR/scale_calibration.json``, which the engine reads with the checkpoint.
"""

import argparse
import dataclasses
from dataclasses import dataclass
import json
import logging
from pathlib import Path
import sys

from infinihand_ros.core.atomic_io import atomic_write_bytes
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.corpus.sample_dataset import SampleDataset
from infinihand_ros.engine.metric_scale import hand_depth_ratios
from infinihand_ros.engine.settings import add_settings_arguments
from infinihand_ros.engine.settings import build_engine_config
from infinihand_ros.engine.settings import checkpoint_overrides
from infinihand_ros.engine.settings import parse_overrides
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.eval.sequences import open_eval_sequence
from infinihand_ros.model.io.bundled import CORRECTION_KEY
from infinihand_ros.model.io.bundled import SCALE_CALIBRATION_FILE
import numpy as np
import torch

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class SequenceCalibration:
    """One sequence's measurement: its correction (median over frames) and frames used."""

    name: str
    correction: float
    frames: int


def frame_correction(true_depth: np.ndarray, depth: np.ndarray, hand_mask: np.ndarray,
                     joints_2d: np.ndarray, joint_depths: np.ndarray) -> float:
    """Return one frame's correction: the scene's true scale over its hands' ratio (NaN: none).

    Args:
        true_depth: (H, W) true depth (m; 0 where nothing).
        depth: (H, W) the engine's depth of the frame (any unit; it cancels).
        hand_mask: (H, W) bool, true hand pixels (left off the scene's scale).
        joints_2d: (N, 21, 2) the engine's hands' joint pixels.
        joint_depths: (N, 21) their metric joint depths (m).

    """
    scene = (true_depth > 0) & (depth > 0) & np.isfinite(depth) & ~hand_mask
    if not scene.any() or not len(joints_2d):
        return float('nan')
    true_scale = float(np.median(true_depth[scene] / depth[scene]))
    ratios = hand_depth_ratios(torch.as_tensor(depth, dtype=torch.float64)[None],
                               torch.zeros(len(joints_2d), dtype=torch.long),
                               torch.as_tensor(joints_2d, dtype=torch.float64),
                               torch.as_tensor(joint_depths, dtype=torch.float64)).numpy()
    ratios = ratios[np.isfinite(ratios) & (ratios > 0)]
    return true_scale / float(np.median(ratios)) if len(ratios) else float('nan')


def calibrate_sequence(path: Path, engine: StreamingEngine, every: int) -> SequenceCalibration:
    """Stream one sample directory through ``engine``; measure every ``every``-th frame."""
    sequence = open_eval_sequence(str(path))
    samples = SampleDataset(path / 'samples' if (path / 'samples').is_dir() else path)
    results = []
    for rgb, stamp, intrinsics in sequence.frames():
        results += engine.push(rgb, stamp, intrinsics)
    results += engine.flush()
    engine.reset()
    values = []
    for result in results:
        if result.frame_index % every or result.depth is None or not result.hands:
            continue
        truth = samples[result.frame_index]
        values.append(frame_correction(
            truth['depth'].numpy(), result.depth, truth['masks'].numpy().any(axis=0),
            np.stack([hand.joints_2d for hand in result.hands]),
            np.stack([hand.joints_cam[:, 2] for hand in result.hands])))
    values = np.array([v for v in values if np.isfinite(v)])
    return SequenceCalibration(sequence.name, float(np.median(values)) if len(values)
                               else float('nan'), len(values))


def build_parser() -> argparse.ArgumentParser:
    """Return the command's argument parser."""
    parser = argparse.ArgumentParser(prog='python -m infinihand_ros.eval.scale_calibration',
                                     description=__doc__.split('\n\n')[0])
    parser.add_argument('--sequences', nargs='+', required=True, type=Path,
                        help='sample directories with true depth (training data, not held-out)')
    parser.add_argument('--checkpoint', help='checkpoint directory or bundled model name')
    add_settings_arguments(parser, 'synthetic')
    parser.add_argument('--every', type=int, default=5, help='measure every n-th frame')
    parser.add_argument('--write', type=Path,
                        help=f'write {SCALE_CALIBRATION_FILE} into this checkpoint directory')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command; print one line per sequence and the correction."""
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s')
    args = build_parser().parse_args(argv)
    if args.every < 1:
        print('--every must be >= 1', file=sys.stderr)
        return 2
    try:
        overrides = {} if args.checkpoint is None else checkpoint_overrides(args.checkpoint)
        overrides.update(parse_overrides(args.overrides))
        config = build_engine_config(args.profile, overrides, args.engine_config)
        # every frame a keyframe with its depth; the correction itself off (it is measured)
        config = dataclasses.replace(
            config, keyframe_interval=1, depth_maps=True, bundle_adjustment=None,
            metric_scale=dataclasses.replace(config.metric_scale, hand_depth_correction=1.0))
        rows = []
        with StreamingEngine(config) as engine:
            for path in args.sequences:
                row = calibrate_sequence(path, engine, args.every)
                print(f'{row.name}: correction {row.correction:.3f} over {row.frames} frames',
                      flush=True)
                rows.append(row)
    except InfiniHandError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    values = np.array([row.correction for row in rows if np.isfinite(row.correction)])
    if not len(values):
        print('error: no frame with both hands and true depth was measured', file=sys.stderr)
        return 1
    result = {CORRECTION_KEY: round(float(np.median(values)), 4),
              'sequences': len(values),
              'p10_p90': [round(float(np.percentile(values, q)), 4) for q in (10, 90)],
              'checkpoint': config.model.checkpoint,
              'measured_on': sorted(row.name for row in rows)}
    print(json.dumps(result))
    if args.write is not None:
        target = args.write / SCALE_CALIBRATION_FILE
        atomic_write_bytes(target, (json.dumps(result, indent=2) + '\n').encode())
        print(f'wrote {target}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
