"""The engine's camera on real pixels with exactly known cameras, tracker on and off.

    python benchmarks/camera_tracking.py [--stills DIR] [--frames N]
        [--geometry-intervals 1 3] [--json]

Builds two streams from the shared real stills (``../shared/data/real_hands_stills``) with
``infinihand_ros.synth.photo_streams`` and runs each through the default engine (bundled model,
real-image hand source, BA off) with the per-frame tracker on, the geometry branch on every
n-th frame for each n of ``--geometry-intervals`` (``engine.geometry_interval``; the frames
between tracked from the image alone; for n > 1 also with its outputs taken in a frame late,
``engine.geometry_lag`` 1, the node's), and with the tracker off (the network's camera as it
is, geometry on every frame):
- still camera, 10 Hz: a real hand and arm moving across a photo; the true pose is the
  identity, so every pose is drift (metres with the engine's metric scale, and degrees);
- turning camera, 10 Hz: views from a camera turned about the photo's centre by up to 10
  degrees (pure rotation, no parallax); rotation error against the exact truth.
Prints the worst and the mean error of each, the tracker's states and its cost per frame.
"""

import argparse
from dataclasses import replace
import json
from pathlib import Path

from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.engine.settings import load_engine_config
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.synth.photo_streams import hand_and_arm_patch
from infinihand_ros.synth.photo_streams import pasted_stream
from infinihand_ros.synth.photo_streams import rotation_stream
from infinihand_ros.synth.photo_streams import wandering_corners
import numpy as np
from scipy.spatial.transform import Rotation
import torch

STILLS = Path(__file__).resolve().parents[2] / 'shared' / 'data' / 'real_hands_stills'


def run(frames: list, tracker: bool, geometry_interval: int, geometry_lag: int
        ) -> tuple[list, dict, int]:
    """Return the results, tracker statistics and frames without geometry of one stream."""
    config = load_engine_config()
    config = replace(config, hands=replace(config.hands, source='mediapipe'),
                     bundle_adjustment=None, tracker=replace(config.tracker, enabled=tracker),
                     geometry_interval=geometry_interval, geometry_lag=geometry_lag)
    with StreamingEngine(config) as engine:
        results = []
        for frame in frames:
            results.extend(engine.push(frame.rgb, frame.timestamp_ns, frame.intrinsics))
        results.extend(engine.flush())
        return (results, engine.statistics['tracker'],
                engine.statistics['frames_without_geometry'])


def main() -> None:
    """Print the still-camera drift and the turning-camera error, tracker on and off."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--stills', type=Path, default=STILLS)
    parser.add_argument('--frames', type=int, default=200, help='frames of the still camera')
    parser.add_argument('--geometry-intervals', type=int, nargs='+', default=[1, 3],
                        help='tracker rows: the geometry branch on every n-th frame')
    parser.add_argument('--geometry-lags', type=int, nargs='+', default=[0, 1],
                        help='for n > 1, rows with the outputs taken in this many frames late '
                        '(engine.geometry_lag; below n)')
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args()
    torch.set_num_threads(1)
    stills = list(read_camera_frames(args.stills))
    patch = hand_and_arm_patch([still.rgb for still in stills])
    if patch is None:
        raise SystemExit('MediaPipe found no hand in the stills')
    background = stills[0]
    corners = wandering_corners(background.rgb.shape[:2], patch.shape[:2], args.frames)
    still = pasted_stream(background.rgb, patch, corners, background.intrinsics)
    steps = np.linspace(0.0, 1.0, 100)
    truth = Rotation.from_rotvec(np.radians(np.stack(
        [5.0 * np.sin(2 * np.pi * steps), 10.0 * np.sin(np.pi * steps), 8.0 * steps],
        axis=1))).as_matrix()
    photo = stills[5]
    turning = rotation_stream(photo.rgb, photo.intrinsics, truth,
                              Intrinsics(400.0, 400.0, 159.5, 119.5, 320, 240))
    report = {}
    runs = [(f'tracker, geometry every {n}' + (f', {lag} frame(s) late' if lag else ''), True,
             n, lag) for n in args.geometry_intervals for lag in args.geometry_lags
            if lag == 0 or lag < n]
    for name, tracker, interval, lag in runs + [('network', False, 1, 0)]:
        results, statistics, skipped = run(still, tracker, interval, lag)
        drift_m = np.array([np.linalg.norm(r.camera_pose.translation) for r in results])
        drift_deg = np.degrees([Rotation.from_matrix(r.camera_pose.rotation).magnitude()
                                for r in results])
        turned, turn_statistics, turn_skipped = run(turning, tracker, interval, lag)
        error_deg = np.degrees([Rotation.from_matrix(r.camera_pose.rotation @ t.T).magnitude()
                                for r, t in zip(turned, truth[0].T @ truth)])
        report[name] = {
            'still_max_m': float(drift_m.max()), 'still_mean_m': float(drift_m.mean()),
            'still_max_deg': float(drift_deg.max()), 'still_mean_deg': float(drift_deg.mean()),
            'turning_max_deg': float(error_deg.max()),
            'turning_mean_deg': float(error_deg.mean()),
            'still_states': statistics['states'], 'turning_states': turn_statistics['states'],
            'without_geometry': (skipped + turn_skipped) / (len(still) + len(turning)),
            'ms_per_frame': (statistics['ms_per_frame'] + turn_statistics['ms_per_frame']) / 2}
    if args.json:
        print(json.dumps(report))
        return
    print(f'still camera ({args.frames} frames, 10 Hz, a real hand and arm moving) and turning '
          'camera (100 frames, pure rotation up to 10 deg), default engine, BA off')
    print('| camera | still: max drift (m) | mean (m) | max (deg) | mean (deg) | '
          'turning: max error (deg) | mean (deg) | tracker ms/frame | frames without geometry |')
    print('|---|---|---|---|---|---|---|---|---|')
    for name, row in report.items():
        print(f"| {name} | {row['still_max_m']:.4f} | {row['still_mean_m']:.4f} | "
              f"{row['still_max_deg']:.3f} | {row['still_mean_deg']:.3f} | "
              f"{row['turning_max_deg']:.3f} | {row['turning_mean_deg']:.3f} | "
              f"{row['ms_per_frame']:.2f} | {100 * row['without_geometry']:.0f} % |")
    for name, *_ in runs:
        print(f"{name}: tracker states: still {report[name]['still_states']}, turning "
              f"{report[name]['turning_states']}")


if __name__ == '__main__':
    main()
