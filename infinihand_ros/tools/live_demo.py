"""``live_demo --out DIR``: the sample bag through the live estimator, recorded, then evaluated.

    live_demo --out DIR [--rate HZ] [--ba none|in_process|node] [--seconds S]

Starts the installed ``estimator`` (and the ``bundle_adjustment`` node with ``--ba node``) on a
private DDS domain, replays the sample bag's camera topics into it at ``--rate`` images per
second (``--seconds``: only the first S seconds of the bag), records its outputs into
``DIR/recorded`` (``live_run``) and stops everything with SIGINT. Then it prints the node's
output rate, latency and drops, and the evaluation of the recorded outputs against the bag's
ground truth (``eval.recorded``: the runner's tables; metrics that need what the node does not
publish are named as not computed), and writes the prediction file and plots into ``DIR/eval``.
Exit codes: 0 done, 1 a process or the evaluation failed, 2 bad arguments.
"""

import argparse
from dataclasses import dataclass
import logging
from pathlib import Path
import sys
from typing import Final

from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.bag.reader import BagReader
from infinihand_ros.core import topics
from infinihand_ros.core.atomic_io import check_writable_location
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.engine.hands.config import HAND_SOURCES
from infinihand_ros.engine.hands.config import INFINIHAND
from infinihand_ros.engine.settings import load_engine_config
from infinihand_ros.eval.cli import mean_pose_joints
from infinihand_ros.eval.cli import save_outputs
from infinihand_ros.eval.recorded import evaluate_recorded
from infinihand_ros.eval.recorded import live_figures
from infinihand_ros.eval.recorded import LiveFigures
from infinihand_ros.eval.recorded import missing_note
from infinihand_ros.eval.recorded import read_recorded
from infinihand_ros.eval.recorded import segment
from infinihand_ros.eval.report import markdown_tables
from infinihand_ros.eval.sequences import open_eval_sequence
from infinihand_ros.ros.estimator.config import BA_MODES
from infinihand_ros.ros.estimator.config import EngineSelection
from infinihand_ros.synth.sample_bag import sample_bag_path
from infinihand_ros.tools.live_run import LiveRunSpec
from infinihand_ros.tools.live_run import recorded_topics
from infinihand_ros.tools.live_run import run_live

EXIT_OK: Final = 0
EXIT_FAILED: Final = 1
EXIT_USAGE: Final = 2
RECORDED_DIR: Final = 'recorded'
EVAL_DIR: Final = 'eval'
LOGS_DIR: Final = 'logs'


@dataclass(frozen=True)
class LiveDemoOptions:
    """Checked command-line options of ``live_demo``."""

    out: Path
    rate_hz: float
    bundle_adjustment: str
    seconds: float
    hand_source: str = INFINIHAND


def parse_args(argv: list[str] | None) -> LiveDemoOptions:
    """Parse and check the arguments; exit 2 with one line naming a bad one."""
    parser = argparse.ArgumentParser(prog='live_demo', description=__doc__.splitlines()[0])
    parser.add_argument('--out', type=Path, required=True,
                        help='output directory: new or empty (recorded/, eval/, logs/)')
    parser.add_argument('--rate', type=float, default=10.0, metavar='HZ',
                        help='images per second replayed into the node (default 10)')
    parser.add_argument('--ba', choices=BA_MODES, default=EngineSelection().bundle_adjustment,
                        help="bundle adjustment: none (the node's default), in_process (the "
                        "engine's worker) or node")
    parser.add_argument('--seconds', type=float, default=0.0, metavar='S',
                        help='replay only the first S seconds of the bag (0: all of it)')
    parser.add_argument('--hand-source', choices=HAND_SOURCES, default=INFINIHAND,
                        help="the node's hands.source (default infinihand: the sample bag is "
                        'synthetic, what the bundled weights were trained on; the node itself '
                        'defaults to mediapipe for real cameras)')
    args = parser.parse_args(argv)
    if not args.rate > 0.0:
        parser.error(f'--rate must be > 0, got {args.rate}')
    if not args.seconds >= 0.0:
        parser.error(f'--seconds must be >= 0, got {args.seconds}')
    if args.out.exists() and (not args.out.is_dir() or any(args.out.iterdir())):
        parser.error(f'--out {args.out} exists and is not an empty directory; choose a new one')
    try:
        check_writable_location(args.out, '--out')
    except InfiniHandError as exc:
        parser.error(str(exc))
    return LiveDemoOptions(args.out, args.rate, args.ba, args.seconds, args.hand_source)


def replayed_stamps(bag: Path, seconds: float) -> set[int]:
    """Return the image stamps ``replay --playback-duration seconds`` publishes (0: all)."""
    wanted = [topics.COMPRESSED_IMAGE_TOPIC, topics.CAMERA_INFO_TOPIC]
    stamps, start = set(), None
    with BagReader(bag) as reader:
        for topic, log_time, msg in reader.messages(wanted):
            start = log_time if start is None else start
            if seconds and (log_time - start) / NS_PER_S >= seconds:
                break
            if topic == topics.COMPRESSED_IMAGE_TOPIC:
                stamps.add(ns_from_stamp(msg.header.stamp))
    return stamps


def figures_lines(figures: LiveFigures, options: LiveDemoOptions, domain_id: int) -> list[str]:
    """Return the report lines on the node's rate, latency and drops."""
    return [
        f'Live estimator (bundle adjustment {options.bundle_adjustment}, DDS domain '
        f'{domain_id}): {figures.images} images replayed at {options.rate_hz:g} Hz',
        f'  output rate {figures.output_rate_hz:.2f} Hz ({figures.outputs} camera poses '
        f'recorded)',
        f'  latency p50 {figures.latency_p50_ms:.0f} ms, p95 {figures.latency_p95_ms:.0f} ms '
        '(image received -> camera pose received, at the recorder)',
        f'  drops: {figures.frames_dropped} dropped by the node (input faster than the model), '
        f'{figures.bad_frames} bad frames, {figures.not_received} never received '
        f'({figures.frames_received} received)',
    ]


@dataclass(frozen=True)
class LiveDemoReport:
    """What a live demo run found: the report it prints, its scores and the node's figures."""

    text: str
    ours: dict[str, float]
    figures: LiveFigures


def run(options: LiveDemoOptions, bag: Path) -> LiveDemoReport:
    """Run the live demo into ``options.out``; return its report."""
    out = options.out
    full = open_eval_sequence(bag)
    stamps = replayed_stamps(bag, options.seconds)
    sequence = segment(full, stamps)
    spec = LiveRunSpec(bag, out / RECORDED_DIR, out / LOGS_DIR, options.rate_hz / full.fps,
                       options.seconds, options.bundle_adjustment, options.hand_source)
    domain_id = run_live(spec)
    recorded = read_recorded(spec.recorded, recorded_topics())
    mean_pose, mean_pose_source = mean_pose_joints(None, load_engine_config(), [sequence])
    evaluation = evaluate_recorded(recorded, sequence, mean_pose)
    save_outputs(out / EVAL_DIR, evaluation.sequences[0], sequence)
    figures = live_figures(recorded, len(stamps))
    return LiveDemoReport('\n'.join([
        *figures_lines(figures, options, domain_id),
        f'  recorded outputs: {spec.recorded}; logs: {spec.logs}', '',
        f"Evaluation of the recorded outputs against the bag's ground truth "
        f'({sequence.truth.num_frames} frames; mean pose: {mean_pose_source}):', '',
        markdown_tables(evaluation), 'Camera-frame joints are the published world joints '
        'mapped by the published camera pose; a published hand counts as detected.',
        missing_note(), '', f'Prediction file and plots: {out / EVAL_DIR}']),
        evaluation.ours, figures)


def main(argv: list[str] | None = None) -> int:
    """Run ``live_demo``; return the exit code."""
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s')
    options = parse_args(argv)
    try:
        print(run(options, sample_bag_path()).text)
    except (InfiniHandError, OSError) as exc:
        print(f'live_demo: {exc}', file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


if __name__ == '__main__':
    sys.exit(main())
