"""MANO-fitting speed and accuracy on one core: frames/s and joint error on known keypoints.

    python benchmarks/mano_fit_speed.py [--frames 100] [--tracks 2] [--json]

Pins the process to one CPU core and one torch thread, draws hand tracks with known built-in
hand parameters (``synth/known_tracks.py``), fits the built-in
hand to their exact joints with the settings of ``config/corpus.yaml`` and prints frames/s and
the mean and maximum joint error in millimetres.
"""

import argparse
import json
import os
from pathlib import Path

from infinihand_ros.core.config import load_config
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.mano.fit import fit_mano
from infinihand_ros.mano.fit import ManoFitConfig
from infinihand_ros.synth.known_tracks import known_track
import numpy as np
import torch

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'corpus.yaml'
SEED = 1
KEYFRAMES = 4


def _parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--frames', type=int, default=100, help='frames per track')
    parser.add_argument('--tracks', type=int, default=2, help='tracks (alternating sides)')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    args = parser.parse_args()
    if args.frames < 3 or args.tracks < 1:
        parser.error(f'--frames must be at least 3 and --tracks at least 1, got {args.frames} '
                     f'and {args.tracks}')
    return args


def main() -> None:
    """Fit the tracks and print the figures."""
    args = _parse_args()
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    torch.set_num_threads(1)
    config = load_config(CONFIG, 'mano_fit', ManoFitConfig)
    rng = np.random.default_rng(SEED)
    frames, seconds, errors = 0, 0.0, []
    for index in range(args.tracks):
        side = index % 2
        result = fit_mano(BuiltinHandModel(side, dtype=torch.float64),
                          known_track(rng, side, args.frames, KEYFRAMES).joints, config=config)
        frames += len(result.joints)
        seconds += result.seconds
        errors.append(result.joint_errors_mm)
    errors_mm = np.concatenate(errors)
    figures = {'frames': frames, 'frames_per_s': frames / seconds,
               'mean_joint_error_mm': float(np.mean(errors_mm)),
               'max_joint_error_mm': float(np.max(errors_mm))}
    if args.json:
        print(json.dumps(figures))
        return
    print(f'MANO fit (built-in hand, one core): {figures["frames_per_s"]:.1f} frames/s over '
          f'{frames} frames; joint error mean {figures["mean_joint_error_mm"]:.3f} mm, max '
          f'{figures["max_joint_error_mm"]:.3f} mm')


if __name__ == '__main__':
    main()
