"""``python -m infinihand_ros.demo``: the main job on the embedded default (``make demo``).

The demo reads the bundled sample bag, regenerates its sequence with the synthetic generator
(bag, training samples, previews) into ``--out`` (replacing only an empty directory or an
earlier demo output) and checks that the fresh ground truth equals the bag's. Then it streams
the bag's frames through the engine with the embedded trained model and sparse bundle
adjustment (the full system, as an offline run: the stream waits for BA and the final, refined
trajectory is scored) and evaluates the estimates against the bag's ground truth (``eval/``):
it prints the evaluation tables (ours beside the baselines) and writes the prediction file and
the plots into ``--out``/eval. Then the live path (``tools/live_demo.py``): the bag replayed at
10 Hz into the installed estimator node, its outputs recorded and evaluated the same way, into
``--out``/live.
"""

import argparse
from collections.abc import Sequence
from pathlib import Path
import sys
from typing import Final

from infinihand_ros.bag.messages import msg_to_frame_result
from infinihand_ros.bag.messages import msg_to_pose
from infinihand_ros.bag.reader import BagReader
from infinihand_ros.core import geometry
from infinihand_ros.core import topics
from infinihand_ros.core.atomic_io import atomic_directory
from infinihand_ros.core.atomic_io import check_writable_location
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.settings import build_engine_config
from infinihand_ros.engine.settings import OFFLINE_BA
from infinihand_ros.engine.settings import parse_overrides
from infinihand_ros.engine.settings import save_engine_settings
from infinihand_ros.engine.settings import SETTINGS_FILE
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.eval.cli import mean_pose_joints
from infinihand_ros.eval.cli import save_outputs
from infinihand_ros.eval.report import markdown_tables
from infinihand_ros.eval.runner import evaluate
from infinihand_ros.eval.runner import Evaluation
from infinihand_ros.eval.sequences import open_eval_sequence
from infinihand_ros.synth import cli
from infinihand_ros.synth.sample_bag import load_sample_settings
from infinihand_ros.synth.sample_bag import sample_bag_path
from infinihand_ros.synth.sample_bag import sample_sequence
from infinihand_ros.tools import live_demo
from infinihand_ros.tools.live_demo import LiveDemoOptions
from infinihand_ros.tools.live_demo import LiveDemoReport
import numpy as np

#: Largest ground-truth difference (m) between the bag and a fresh generation that still counts
#: as the same sequence (the bag stores float64, so this is rounding only).
SAME_SEQUENCE_TOLERANCE_M: Final = 1e-9

#: File the demo writes into its output directory; only a directory holding it (or an empty or
#: missing one) is replaced by a later run, so the demo never deletes what it did not write.
OUTPUT_MARKER: Final = '.infinihand_demo'
#: The resolved engine configuration the demo ran with, saved beside its outputs.
#: The engine settings profile of the offline run (the sample bag is synthetic).
PROFILE: Final = 'synthetic'
#: Folder of ``--out`` with the evaluation's prediction file and plots.
EVAL_DIR: Final = 'eval'
#: Folder of ``--out`` with the live run (recording, logs, its evaluation), and its replay rate.
LIVE_DIR: Final = 'live'
LIVE_RATE_HZ: Final = 10.0


def read_ground_truth(bag: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return camera positions (T, 3), wrist positions (T, 2, 3) and visibility (T, 2) of a bag.

    Hands absent from a frame have NaN wrists and visibility False (index 0 left, 1 right).
    """
    positions, wrists, visible = [], [], []
    with BagReader(bag) as reader:
        for topic, _, msg in reader.messages([topics.GT_CAMERA_POSE_TOPIC,
                                              topics.GT_HANDS_TOPIC]):
            if topic == topics.GT_CAMERA_POSE_TOPIC:
                positions.append(msg_to_pose(msg.pose).translation)
                continue
            frame_wrists, frame_visible = np.full((2, 3), np.nan), np.zeros(2, dtype=bool)
            for hand in msg_to_frame_result(msg).hands:
                frame_wrists[hand.side] = hand.joints_world[0]
                frame_visible[hand.side] = hand.confidence > 0.5
            wrists.append(frame_wrists)
            visible.append(frame_visible)
    return np.array(positions), np.array(wrists), np.array(visible)


def describe_bag(bag: Path) -> str:
    """Return a few lines on a bag: size, duration and topics."""
    size = sum(f.stat().st_size for f in bag.iterdir()) / 2**20
    with BagReader(bag) as reader:
        lines = [f'{bag} ({size:.1f} MiB, {reader.duration_s():.1f} s)']
        lines += [f'  {topic:32s} {info.count:5d} x {info.msgtype}'
                  for topic, info in sorted(reader.topics().items())]
    return '\n'.join(lines)


def evaluate_bag(bag: Path, config: EngineConfig, out: Path) -> tuple[str, Evaluation]:
    """Run the engine over the bag, evaluate it against the bag's ground truth.

    Writes the prediction file and the plots into ``out``; returns the report and the scores.
    """
    sequence = open_eval_sequence(bag)
    mean_pose, mean_pose_source = mean_pose_joints(None, config, [sequence])
    evaluation = evaluate([sequence], lambda: StreamingEngine(config), mean_pose)
    save_outputs(out, evaluation.sequences[0], sequence)
    checkpoint = config.model.checkpoint or f'seeded weights (seed {config.model.seed})'
    ba = 'off' if config.bundle_adjustment is None else 'on'
    return '\n'.join([
        f'Engine ({checkpoint}, {config.mode} mode, bundle adjustment {ba}, final trajectory) '
        'on the bag: '
        f'{evaluation.ours["frames/s"]:.1f} frames/s; evaluation against its ground truth '
        f'(mean pose: {mean_pose_source}):', '', markdown_tables(evaluation)]), evaluation


def side_by_side(offline: Evaluation, live: LiveDemoReport) -> str:
    """Return a table: the offline full system beside the live node, and the baselines."""
    rows = [('offline: engine + BA, final trajectory', offline.ours),
            (f'live node at {LIVE_RATE_HZ:g} Hz, as published '
             f'({live.figures.outputs} of {live.figures.images} frames)', live.ours),
            ('still camera', offline.baselines['static-camera']),
            ('constant skeleton (mean hand)', offline.baselines['mean-hand'])]
    lines = ['| on the sample bag | W-MPJPE (mm) | ATE (m) | RPE-r (deg) |', '|---|---|---|---|']
    for name, scores in rows:
        cells = [scores.get(key, float('nan')) for key in ('W-MPJPE', 'ATE', 'RPE-r')]
        lines.append(f'| {name} | ' + ' | '.join(
            '-' if cell != cell else f'{cell:.4g}' for cell in cells) + ' |')
    return '\n'.join(lines)


def validate_out(out: Path) -> None:
    """Check that ``out`` is missing, an empty directory or an earlier demo output.

    Raises:
        InfiniHandError: naming ``out`` when it is a file, holds files the demo did not write
            (no ``OUTPUT_MARKER``) or cannot be created.

    """
    if out.exists() and not out.is_dir():
        raise InfiniHandError(f'--out {out} is a file, not a directory; choose another path')
    if out.is_dir() and any(out.iterdir()) and not (out / OUTPUT_MARKER).is_file():
        raise InfiniHandError(f'--out {out} holds files the demo did not write (no '
                              f'{OUTPUT_MARKER} marker) and would be replaced; choose another '
                              'path or empty it yourself')
    check_writable_location(out, '--out')


def run(out: Path, bag: Path, overrides: Sequence[str] = ()) -> str:
    """Run the demo into ``out`` (checked by ``validate_out``); return the report it prints.

    The offline run uses the ``synthetic`` profile with bundle adjustment as offline runs have
    it, then ``overrides`` (``--set``).
    """
    validate_out(out)
    settings = load_sample_settings()
    report = ['Embedded sample bag:', describe_bag(bag)]
    cameras, wrists, visible = read_ground_truth(bag)
    applied = {**OFFLINE_BA, **parse_overrides(overrides)}
    engine_config = build_engine_config(PROFILE, applied)
    with atomic_directory(out, overwrite=True) as work:
        summary = cli.generate(settings.synth, settings.spec.seed, settings.spec.frames, work,
                               settings.bag)
        fresh_cameras, fresh_wrists, _ = read_ground_truth(work / cli.BAG_DIR)
        (work / OUTPUT_MARKER).write_text('Written by python -m infinihand_ros.demo, which '
                                          'replaces this directory on its next run.\n')
        save_engine_settings(engine_config, work / SETTINGS_FILE, PROFILE, applied)
        evaluation, offline = evaluate_bag(bag, engine_config, work / EVAL_DIR)
        live = live_demo.run(LiveDemoOptions(work / LIVE_DIR, LIVE_RATE_HZ, 'none', 0.0), bag)
        live_text = live.text.replace(str(work), str(out))  # the final paths, not the staging
    if fresh_cameras.shape != cameras.shape:
        raise InfiniHandError(f'{bag} holds {len(cameras)} frames but its settings give '
                              f'{len(fresh_cameras)}; regenerate it with '
                              'python -m infinihand_ros.synth.sample_bag --write')
    difference = max(np.abs(fresh_cameras - cameras).max(),
                     np.nanmax(np.abs(fresh_wrists - wrists), initial=0.0))
    sequence = sample_sequence(settings)
    angles = geometry.rotation_angle_deg(sequence.T_scene_cams[:1, :3, :3],
                                         sequence.T_scene_cams[:, :3, :3])
    fov_h, fov_w = np.degrees(sequence.intrinsics.fov())
    report += [
        '',
        f"Regenerated seed {settings.spec.seed} into {out} at {summary['fps']:.1f} frames/s "
        f"({summary['frames']} frames in {summary['seconds']:.1f} s):",
        f'  ground truth identical to the bag: {difference <= SAME_SEQUENCE_TOLERANCE_M} '
        f'(max difference {difference:.1e} m)',
        f'  camera: path {np.linalg.norm(np.diff(cameras, axis=0), axis=1).sum():.2f} m, '
        f'head turns up to {angles.max():.0f} deg, FoV {fov_w:.0f} x {fov_h:.0f} deg',
        f'  hands visible: left {visible[:, 0].mean():.0%}, right {visible[:, 1].mean():.0%} '
        'of frames',
        f'  previews: {out / cli.FRAMES_PREVIEW}, {out / cli.TRAJECTORY_PREVIEW}',
        f'  bag: {out / cli.BAG_DIR}; training samples: {out / cli.SAMPLES_DIR}',
        f'  resolved engine settings: {out / SETTINGS_FILE}',
        '',
        evaluation,
        f'Prediction file and plots: {out / EVAL_DIR}',
        '',
        f'Live path (replay at {LIVE_RATE_HZ:g} Hz -> estimator node -> record), in '
        f'{out / LIVE_DIR}:',
        live_text,
        '',
        'Offline and live side by side:',
        side_by_side(offline, live),
    ]
    return '\n'.join(report)


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    parser = argparse.ArgumentParser(prog='python -m infinihand_ros.demo',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--out', type=Path, default=Path('out/demo'),
                        help='output directory: new, empty or an earlier demo output '
                             '(replaced atomically; default out/demo)')
    parser.add_argument('--set', dest='overrides', action='append', default=[],
                        metavar='KEY=VALUE',
                        help=f'override one engine setting of the offline run (profile '
                             f'{PROFILE}, with bundle adjustment); repeatable')
    args = parser.parse_args(argv)
    try:
        print(run(args.out, sample_bag_path(), args.overrides))
    except InfiniHandError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:  # e.g. the disk filled up while writing
        print(f'error: writing --out {args.out} failed: {exc}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
