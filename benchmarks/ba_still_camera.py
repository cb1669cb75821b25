"""A still webcam through the converter's settings, BA on and off: the drift a dataset gets.

    python benchmarks/ba_still_camera.py [--stills DIR] [--frames N] [--json]

A real photo (``../shared/data/real_hands_stills``) with a real hand and arm pasted at positions
that move across it, at 10 Hz (the converter's rate), with fresh sensor noise and JPEG
compression on every frame (``synth.photo_streams.as_webcam``) and no intrinsics given (a
webcam without calibration). The true pose is the identity in every frame, so every pose is
drift. Runs ``bag_to_dataset``'s engine settings with BA (its default) and without, and prints
the worst and the mean drift (metres at the engine's metric scale, and degrees) of the tracker,
the live poses and the final, refined trajectory that the converter writes.
"""

import argparse
from dataclasses import replace
import json
from pathlib import Path

from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.convert.config import load_convert_config
from infinihand_ros.convert.run import engine_config_for
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.synth.photo_streams import as_webcam
from infinihand_ros.synth.photo_streams import hand_and_arm_patch
from infinihand_ros.synth.photo_streams import pasted_stream
from infinihand_ros.synth.photo_streams import wandering_corners
import numpy as np
from records import add_record_option
from records import Figure
from records import write_record
from scipy.spatial.transform import Rotation

STILLS = Path(__file__).resolve().parents[2] / 'shared' / 'data' / 'real_hands_stills'


def still_webcam(stills: list, frames: int) -> list:
    """Return ``frames`` frames of the still webcam stream built from the real stills."""
    patch = hand_and_arm_patch([still.rgb for still in stills])
    if patch is None:
        raise SystemExit('MediaPipe found no hand in the stills')
    background = stills[0]
    corners = wandering_corners(background.rgb.shape[:2], patch.shape[:2], frames)
    return as_webcam(pasted_stream(background.rgb, patch, corners, background.intrinsics))


def drift(poses: list) -> dict[str, float]:
    """Return the worst and mean distance (m) and angle (deg) of poses from the identity."""
    metres = np.array([np.linalg.norm(pose.translation) for pose in poses])
    degrees = np.degrees([Rotation.from_matrix(pose.rotation).magnitude() for pose in poses])
    return {'max_m': float(metres.max()), 'mean_m': float(metres.mean()),
            'max_deg': float(degrees.max()), 'mean_deg': float(degrees.mean())}


def run(frames: list, with_ba: bool) -> dict[str, dict[str, float]]:
    """Stream the frames with the converter's settings; return each trajectory's drift."""
    config = engine_config_for(load_convert_config())
    if not with_ba:
        config = replace(config, bundle_adjustment=None)
    with StreamingEngine(config) as engine:
        live = []
        for frame in frames:
            live += engine.push(frame.rgb, frame.timestamp_ns, None)
        live += engine.flush()
        final = engine.refined(live)
    return {'tracker': drift([r.raw_camera_pose or r.camera_pose for r in final]),
            'live': drift([r.camera_pose for r in live]),
            'final': drift([r.camera_pose for r in final])}


def record_figures(report: dict, frames: int) -> list[Figure]:
    """Return the written (final) trajectory's worst drift, BA on and off, as record figures."""
    figures = []
    for name, rows in report.items():
        label = f'still webcam, {frames} frames, {name}: worst drift of the written trajectory'
        figures += [Figure(label, 1e3 * rows['final']['max_m'], 'mm'),
                    Figure(label, rows['final']['max_deg'], 'deg')]
    return figures


def main() -> None:
    """Print the drift of each trajectory, BA on and off."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--stills', type=Path, default=STILLS)
    parser.add_argument('--frames', type=int, default=200)
    parser.add_argument('--json', action='store_true')
    add_record_option(parser)
    args = parser.parse_args()
    frames = still_webcam(list(read_camera_frames(args.stills)), args.frames)
    report = {'BA on (default)': run(frames, True), 'BA off': run(frames, False)}
    write_record(args.record, 'ba_still_camera', record_figures(report, args.frames))
    if args.json:
        print(json.dumps(report))
        return
    print(f'still webcam ({args.frames} frames at 10 Hz, a real hand and arm moving, noise and '
          'JPEG per frame, no intrinsics), bag_to_dataset settings')
    print('| run | trajectory | max drift (m) | mean (m) | max (deg) | mean (deg) |')
    print('|---|---|---|---|---|---|')
    for name, rows in report.items():
        for trajectory, row in rows.items():
            print(f"| {name} | {trajectory} | {row['max_m']:.4f} | {row['mean_m']:.4f} | "
                  f"{row['max_deg']:.3f} | {row['mean_deg']:.3f} |")


if __name__ == '__main__':
    main()
