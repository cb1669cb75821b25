"""Where the world-space error comes from: our hands or our camera (held-out sequences).

    python benchmarks/eval_error_sources.py --sequences runs/heldout/* [--checkpoint CK] [--json]

Takes the options of ``python -m infinihand_ros.eval`` (``--checkpoint``, ``--engine-config``,
``--mode``, ``--ba``, ``--poses``, ``--json``; the others are ignored), runs the engine over each
sequence as it does (the same appendix-A matching and hand-frame pairs) and scores three
placements of the hands in the world with the evaluation's W-MPJPE and WA-MPJPE:

- ``ours``: our camera-frame hands with our camera (the evaluation's figure);
- ``true camera``: our camera-frame hands with the ground-truth camera (the hands' share);
- ``true hands``: the ground-truth camera-frame hands with our camera (the camera's share).

Then, by frame range, the camera's rotation error (degrees, against the truth in the first
camera's frame), the error of its frame-to-frame turn and the truth's own frame-to-frame turn:
an error that grows along the stream is drift; a turn error above the true turn is noise worse
than holding still. Figures only; nothing is asserted.
"""

import json
import sys

from infinihand_ros.core.geometry import rotation_angle_deg
from infinihand_ros.core.geometry import transform_points
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.eval.cli import build_parser
from infinihand_ros.eval.cli import engine_config
from infinihand_ros.eval.metrics import world_space
from infinihand_ros.eval.runner import eval_frames
from infinihand_ros.eval.runner import run_engine
from infinihand_ros.eval.runner import scored_pairs
from infinihand_ros.eval.sequences import open_eval_sequence
import numpy as np

#: Frame ranges [start, end) of the rotation-error table.
FRAME_RANGES = ((1, 5), (5, 10), (10, 20), (20, 40), (40, 80), (80, 10_000))
PLACEMENTS = ('ours', 'true camera', 'true hands')


def sequence_figures(path: str, engine: StreamingEngine, poses: str = 'final') -> dict:
    """Run one sequence; return W/WA-MPJPE per placement and per-frame rotation errors."""
    sequence = open_eval_sequence(path)
    truth = sequence.truth
    pred = run_engine(sequence, engine, poses)
    engine.reset()
    pairs = scored_pairs(eval_frames(sequence, pred), pred)
    posed = np.where(pred.has_result[:, None, None], pred.T_world_cam, truth.T_world_cam)
    worlds = {'ours': pred.joints_world,
              'true camera': transform_points(truth.T_world_cam[:, None],
                                              np.nan_to_num(pred.joints_cam)),
              'true hands': transform_points(posed[:, None], truth.joints_cam)}
    scores = {name: world_space(joints, truth.joints_world, pairs) if pairs.any() else {}
              for name, joints in worlds.items()}
    rotations, true_rotations = posed[:, :3, :3], truth.T_world_cam[:, :3, :3]
    error = rotation_angle_deg(rotations, true_rotations)
    steps = np.swapaxes(true_rotations[:-1], -1, -2) @ true_rotations[1:]
    our_steps = np.swapaxes(rotations[:-1], -1, -2) @ rotations[1:]
    step_error = rotation_angle_deg(our_steps, steps)
    error[~pred.has_result] = np.nan  # frames without a result are not scored
    step_error[~(pred.has_result[:-1] & pred.has_result[1:])] = np.nan
    return {'name': sequence.name, 'pairs': int(pairs.sum()), 'scores': scores,
            'rotation_error_deg': error.tolist(),
            'step_error_deg': [0.0, *step_error.tolist()],
            'true_step_deg': [0.0, *rotation_angle_deg(steps, np.eye(3)).tolist()]}


def summary(figures: list[dict]) -> dict:
    """Return the per-placement means over sequences and the rotation error by frame range."""
    def mean(name: str, key: str) -> float:
        return float(np.mean([f['scores'][name][key] for f in figures if f['scores'][name]]))

    placements = {name: {key: mean(name, key) for key in ('W-MPJPE', 'WA-MPJPE')}
                  for name in PLACEMENTS}
    ranges = []
    for start, end in FRAME_RANGES:
        errors = [e for f in figures for e in f['rotation_error_deg'][start:end]]
        step_errors = [s for f in figures for s in f['step_error_deg'][start:end]]
        steps = [s for f in figures for s in f['true_step_deg'][start:end]]
        if errors:
            last = min(end, max(len(f['true_step_deg']) for f in figures))
            ranges.append({'frames': f'{start}-{last}',
                           'rotation_error_deg': float(np.nanmean(errors)),
                           'step_error_deg': float(np.nanmean(step_errors)),
                           'true_step_deg': float(np.mean(steps))})
    return {'placements': placements, 'rotation_by_frames': ranges}


def print_tables(result: dict) -> None:
    """Print the two markdown tables."""
    print('| placement | W-MPJPE (mm) | WA-MPJPE (mm) |\n|---|---|---|')
    for name, values in result['placements'].items():
        print(f"| {name} | {values['W-MPJPE']:.1f} | {values['WA-MPJPE']:.1f} |")
    print('\n| frames | rotation error (deg) | turn error (deg) | true turn (deg) |')
    print('|---|---|---|---|')
    for row in result['rotation_by_frames']:
        print(f"| {row['frames']} | {row['rotation_error_deg']:.1f} "
              f"| {row['step_error_deg']:.2f} | {row['true_step_deg']:.2f} |")


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; return the exit code."""
    args = build_parser().parse_args(argv)
    with StreamingEngine(engine_config(args)) as engine:
        figures = [sequence_figures(path, engine, args.poses) for path in sorted(args.sequences)]
    result = summary(figures)
    if args.json:
        print(json.dumps(result))
    else:
        print_tables(result)
    return 0


if __name__ == '__main__':
    sys.exit(main())
