"""``python -m infinihand_ros.eval``: run the engine over held-out sequences, print the tables.

Prints the paper's tables (ours beside the baselines) as markdown, or with ``--json`` one JSON
line; ``--save-predictions DIR`` writes ``<name>.npz`` per sequence (``prediction_files``) and
the PNG plots (``plots``). Exit codes: 0 done, 1 a sequence failed to run or write, 2 usage.
"""

import argparse
from dataclasses import dataclass
import json
import logging
from pathlib import Path
import sys

from infinihand_ros.core.atomic_io import check_writable_location
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.settings import add_settings_arguments
from infinihand_ros.engine.settings import build_engine_config
from infinihand_ros.engine.settings import checkpoint_overrides
from infinihand_ros.engine.settings import OFFLINE_BA
from infinihand_ros.engine.settings import parse_overrides
from infinihand_ros.engine.settings import save_engine_settings
from infinihand_ros.engine.settings import SETTINGS_FILE
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.eval import baselines
from infinihand_ros.eval.plots import write_plots
from infinihand_ros.eval.prediction_files import write_predictions
from infinihand_ros.eval.report import json_line
from infinihand_ros.eval.report import markdown_tables
from infinihand_ros.eval.report import sequence_table
from infinihand_ros.eval.runner import evaluate
from infinihand_ros.eval.runner import Evaluation
from infinihand_ros.eval.runner import POSES
from infinihand_ros.eval.runner import SequenceEvaluation
from infinihand_ros.eval.sequences import EvalSequence
from infinihand_ros.eval.sequences import open_eval_sequence
from infinihand_ros.model.io.bundled import MEAN_POSE_FILE
from infinihand_ros.model.io.bundled import resolve_checkpoint
import numpy as np

logger = logging.getLogger(__name__)


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser."""
    parser = argparse.ArgumentParser(
        prog='python -m infinihand_ros.eval',
        description='Evaluate the streaming engine on sequences with ground truth (sample '
                    'directories, generator outputs or bags with /ground_truth topics).')
    parser.add_argument('--sequences', nargs='+', required=True, help='held-out sequences')
    parser.add_argument('--checkpoint', help='whole-model checkpoint directory (default: the '
                                             "engine config's, i.e. the embedded model)")
    add_settings_arguments(parser, 'synthetic')
    parser.add_argument('--ba', action='store_true',
                        help='run bundle adjustment (config/ba.yaml; the stream waits for BA '
                             'instead of dropping pool selections, as an offline run should)')
    parser.add_argument('--poses', choices=POSES, default='final',
                        help='final (default): score the trajectory known at the end (BA '
                             'corrections and the final metric scale on every frame); live: '
                             'each frame as the engine published it')
    parser.add_argument('--mean-pose', help=f'JSON with the training mean articulation '
                                            f'(default: {MEAN_POSE_FILE} in the checkpoint; '
                                            "else the evaluated sequences' own mean)")
    parser.add_argument('--json', action='store_true', help='print one JSON line')
    parser.add_argument('--save-predictions', type=Path,
                        help='write <name>.npz and PNG plots per sequence here')
    return parser


def engine_config(args: argparse.Namespace) -> EngineConfig:
    """Return the engine settings the arguments ask for (profile, file, --ba, --set)."""
    overrides: dict[str, object] = {}
    if args.checkpoint is not None:
        resolve_checkpoint(args.checkpoint)  # a directory or a bundled name, else an error
        overrides.update(checkpoint_overrides(args.checkpoint))
    if args.ba:
        overrides.update(OFFLINE_BA)
    overrides.update(parse_overrides(args.overrides))
    return build_engine_config(args.profile, overrides, args.engine_config)


def mean_pose_joints(explicit: str | None, config: EngineConfig,
                     sequences: list[EvalSequence]) -> tuple[np.ndarray, str]:
    """Return the mean-pose skeletons (2, 21, 3) and where the articulation came from.

    From ``explicit`` (a JSON file) when given, else the checkpoint's ``mean_pose.json``, else
    (with a warning) the evaluated sequences' own mean articulation.
    """
    source = explicit
    if source is None and config.model.checkpoint is not None:
        candidate = resolve_checkpoint(config.model.checkpoint) / MEAN_POSE_FILE
        source = str(candidate) if candidate.is_file() else None
    if source is not None:
        try:
            pose = np.asarray(json.loads(Path(source).read_text(encoding='utf-8'))['hand_pose'],
                              dtype=np.float64).reshape(15, 3)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise InfiniHandError(f'--mean-pose {source}: expected JSON with "hand_pose" '
                                  f'(15 x 3 axis-angles) ({exc})') from exc
        return baselines.mean_pose_joints(pose), f'training set ({source})'
    poses = [seq.truth.hand_pose[seq.truth.visible[:, side], side]
             for seq in sequences for side in (0, 1)]
    sides = [side for _ in sequences for side in (0, 1)]
    logger.warning('no training mean pose (--mean-pose or %s in the checkpoint): the mean-pose '
                   "baseline uses the evaluated sequences' own mean articulation",
                   MEAN_POSE_FILE)
    return (baselines.mean_pose_joints(baselines.mean_articulation(poses, sides)),
            'evaluated sequences')


def save_outputs(directory: Path, evaluation: SequenceEvaluation,
                 sequence: EvalSequence) -> None:
    """Write the prediction file and the plots of one sequence."""
    write_predictions(directory / f'{evaluation.name}.npz', evaluation.predictions)
    truth = sequence.truth
    write_plots(directory, evaluation, truth.T_world_cam, truth.joints_world, truth.visible)


@dataclass(frozen=True)
class EvaluationPlan:
    """Everything checked before the first frame runs."""

    config: EngineConfig
    sequences: list[EvalSequence]
    mean_pose: np.ndarray
    mean_pose_source: str
    poses: str
    profile: str


def prepare(args: argparse.Namespace) -> EvaluationPlan:
    """Check the arguments, open the sequences and the mean pose (InfiniHandError naming them)."""
    config = engine_config(args)
    sequences = [open_eval_sequence(path) for path in args.sequences]
    names = [sequence.name for sequence in sequences]
    if len(set(names)) != len(names):
        raise InfiniHandError(f'--sequences: names must be unique (they name the output '
                              f'files), got {names}')
    if args.save_predictions is not None:
        check_writable_location(args.save_predictions, '--save-predictions')
        args.save_predictions.mkdir(parents=True, exist_ok=True)
        save_engine_settings(config, args.save_predictions / SETTINGS_FILE, args.profile,
                             args.overrides)
    joints, source = mean_pose_joints(args.mean_pose, config, sequences)
    return EvaluationPlan(config, sequences, joints, source, args.poses, args.profile)


def execute(plan: EvaluationPlan, save_to: Path | None
            ) -> tuple[Evaluation, dict[str, object]]:
    """Run the plan; return the evaluation and the settings it ran with."""
    by_name = {sequence.name: sequence for sequence in plan.sequences}

    def on_sequence(evaluation: SequenceEvaluation) -> None:
        ours = evaluation.ours
        logger.info('%s: %d frames, W-MPJPE %.1f mm, ATE %.3f m, %.1f frames/s',
                    evaluation.name, evaluation.num_frames, ours.get('W-MPJPE', np.nan),
                    ours.get('ATE', np.nan), evaluation.predictions.frames_per_s)
        if save_to is not None:
            save_outputs(save_to, evaluation, by_name[evaluation.name])

    config = plan.config
    evaluation = evaluate(plan.sequences, lambda: StreamingEngine(config), plan.mean_pose,
                          on_sequence, plan.poses)
    settings = {'profile': plan.profile, 'checkpoint': config.model.checkpoint,
                'mode': config.mode,
                'hand_source': config.hands.source,
                'bundle_adjustment': config.bundle_adjustment is not None,
                'poses': plan.poses, 'mean_pose': plan.mean_pose_source}
    return evaluation, settings


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s')
    args = build_parser().parse_args(argv)
    try:
        plan = prepare(args)
    except InfiniHandError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    try:
        evaluation, settings = execute(plan, args.save_predictions)
    except (InfiniHandError, OSError) as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    if args.json:
        print(json_line(evaluation, settings))
    else:
        print(f"profile: {settings['profile']}, hand source: {settings['hand_source']}, "
              f"poses: {settings['poses']}\n")
        print(markdown_tables(evaluation))
        print(sequence_table(evaluation))
    return 0
