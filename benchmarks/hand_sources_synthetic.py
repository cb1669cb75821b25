"""The two hand sources side by side on synthetic ground truth (held-out sequences).

    python benchmarks/hand_sources_synthetic.py --sequences runs/heldout/* [--json]

Takes the options of ``python -m infinihand_ros.eval`` (``--checkpoint``, ``--engine-config``,
``--mode``, ``--poses``, ``--json``; the others are ignored) and runs the engine over each
sequence once per hand source, ``infinihand`` (the paper's hand branch) and ``mediapipe``
(MediaPipe Hands lifted to MANO), all else equal. It prints per source:

- the paper's figures over every on-screen hand (appendix A: recall, and MP-p, PA-p, EPE-p with
  the missed-hand penalty), pooled over the sequences;
- the same camera-space errors without penalty on the hands both sources found (the same
  target hand matched by both in the same frame), and the world-space W-MPJPE and WA-MPJPE of
  those hand-frames (mean over the sequences that have any).

MediaPipe finds about 60 % of the synthetic hands (``benchmarks/synth_realism.py``), so the
penalised figures of the mediapipe source are much affected by its misses; the common set
compares the two on the same hands. Figures only; nothing is asserted.
"""

from dataclasses import replace
import json
import sys

from infinihand_ros.engine.hands.config import HAND_SOURCES
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.eval.cli import build_parser
from infinihand_ros.eval.cli import engine_config
from infinihand_ros.eval.matching import EvalFrame
from infinihand_ros.eval.metrics import camera_space_metrics
from infinihand_ros.eval.metrics import detection_metrics
from infinihand_ros.eval.metrics import match_frames
from infinihand_ros.eval.metrics import world_space
from infinihand_ros.eval.runner import eval_frames
from infinihand_ros.eval.runner import run_engine
from infinihand_ros.eval.runner import scored_pairs
from infinihand_ros.eval.sequences import open_eval_sequence
import numpy as np

CAMERA_KEYS = ('MP-p', 'PA-p', 'EPE-p', 'CT-p')


def _common_frames(frames: list[EvalFrame], matches: list, common: list[set[int]]
                   ) -> list[EvalFrame]:
    """Return the frames cut down to the common targets and this source's matches of them."""
    return [replace(frame, targets=[frame.targets[t] for t in keep],
                    predictions=[frame.predictions[p] for t, p in match.matched if t in keep])
            for frame, match, keep in zip(frames, matches, common) if keep]


def sequence_runs(path: str, engines: dict[str, StreamingEngine], poses: str) -> dict:
    """Run one sequence with each source; return its frames, matches and world figures."""
    sequence = open_eval_sequence(path)
    truth = sequence.truth
    runs = {}
    for name, engine in engines.items():
        pred = run_engine(sequence, engine, poses)
        engine.reset()
        frames = eval_frames(sequence, pred)
        runs[name] = {'pred': pred, 'frames': frames, 'matches': match_frames(frames),
                      'pairs': scored_pairs(frames, pred)}
    first, second = runs.values()
    common = [{t for t, _ in a.matched} & {t for t, _ in b.matched}
              for a, b in zip(first['matches'], second['matches'])]
    pairs = first['pairs'] & second['pairs']
    for run in runs.values():
        run['common'] = _common_frames(run['frames'], run['matches'], common)
        run['world'] = (world_space(run['pred'].joints_world, truth.joints_world, pairs)
                        if pairs.sum() else None)
    return {'name': sequence.name, 'runs': runs, 'common_pairs': int(pairs.sum())}


def summary(results: list[dict]) -> dict:
    """Return per source: the paper's pooled figures and the figures on the common hands."""
    report = {}
    for name in HAND_SOURCES:
        frames = [f for r in results for f in r['runs'][name]['frames']]
        matches = [m for r in results for m in r['runs'][name]['matches']]
        common = [f for r in results for f in r['runs'][name]['common']]
        worlds = [r['runs'][name]['world'] for r in results if r['runs'][name]['world']]
        report[name] = {
            'all': {**detection_metrics(frames, matches).as_dict(),
                    **camera_space_metrics(frames, matches=matches).as_dict()},
            'common': camera_space_metrics(common).as_dict() if common else {},
            'common_world': {key: float(np.mean([w[key] for w in worlds]))
                             for key in ('W-MPJPE', 'WA-MPJPE')} if worlds else {}}
    report['common_hands'] = sum(len(f.targets) for r in results
                                 for f in r['runs'][HAND_SOURCES[0]]['common'])
    report['common_sequences'] = sum(r['common_pairs'] > 0 for r in results)
    report['sequences'] = len(results)
    return report


def print_tables(report: dict) -> None:
    """Print the two markdown tables."""
    print(f"{report['sequences']} sequences; hands found by both sources: "
          f"{report['common_hands']} (in {report['common_sequences']} sequences)\n")
    print('| source | Recall | MP-p (mm) | PA-p (mm) | EPE-p (px) |\n|---|---|---|---|---|')
    for name in HAND_SOURCES:
        row = report[name]['all']
        print(f"| {name} | {row['Recall']:.3f} | {row['MP-p']:.1f} | {row['PA-p']:.1f} "
              f"| {row['EPE-p']:.1f} |")
    print('\nOn the hands both found (no penalty):\n')
    print('| source | MP (mm) | PA (mm) | EPE (px) | CT (m) | W-MPJPE (mm) | WA-MPJPE (mm) |')
    print('|---|---|---|---|---|---|---|')
    for name in HAND_SOURCES:
        row, world = report[name]['common'], report[name]['common_world']
        if row:
            print(f"| {name} | {row['MP-p']:.1f} | {row['PA-p']:.1f} | {row['EPE-p']:.1f} "
                  f"| {row['CT-p']:.3f} | {world.get('W-MPJPE', float('nan')):.1f} "
                  f"| {world.get('WA-MPJPE', float('nan')):.1f} |")


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; return the exit code."""
    args = build_parser().parse_args(argv)
    config = engine_config(args)
    engines = {name: StreamingEngine(replace(config, hands=replace(config.hands, source=name)))
               for name in HAND_SOURCES}
    try:
        results = [sequence_runs(path, engines, args.poses) for path in sorted(args.sequences)]
    finally:
        for engine in engines.values():
            engine.close()
    report = summary(results)
    if args.json:
        print(json.dumps(report))
    else:
        print_tables(report)
    return 0


if __name__ == '__main__':
    sys.exit(main())
