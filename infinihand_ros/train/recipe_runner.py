"""Run a recipe (``recipe.py``) from its data to its evaluations; every step resumes.

``python -m infinihand_ros.train.recipe_runner RECIPE [--runs runs] [--jobs 2] [--dry-run]``
(what ``scripts/train_embedded_model.sh`` runs with ``models/tiny_synthetic/recipe.yaml``):

1. the training sets (``synth.batch``, one process per seed range, ``--jobs`` at a time; seeds
   already written are skipped) and the evaluation sets (``synth``, one sequence per seed,
   skipped when written; its bag is removed, the training samples kept);
2. every stage in order (``train``, under ``torch.distributed.run`` with more than one
   process): a stage with a final model is skipped, one with checkpoints continues from the
   newest (``--resume``), any other starts with its setting's config and ``--set`` values;
3. the export of the last stage to ``runs/<export.out>`` and the evaluations, each report
   printed and written to ``runs/<name>.md``.

``--dry-run`` prints the commands (those of the steps still to do) and runs nothing.
"""

import argparse
from collections.abc import Sequence
import logging
from pathlib import Path
import shlex
import shutil
import subprocess
import sys
from typing import Final

from infinihand_ros.core.atomic_io import atomic_directory
from infinihand_ros.core.config import read_yaml
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.model.io.checkpoint import GEOMETRY_FILE
from infinihand_ros.model.io.checkpoint import WEIGHTS_FILE
from infinihand_ros.train.recipe import eval_sequence_command
from infinihand_ros.train.recipe import evaluation_command
from infinihand_ros.train.recipe import export_command
from infinihand_ros.train.recipe import final_model
from infinihand_ros.train.recipe import load_recipe
from infinihand_ros.train.recipe import Recipe
from infinihand_ros.train.recipe import Stage
from infinihand_ros.train.recipe import stage_init
from infinihand_ros.train.recipe import train_command
from infinihand_ros.train.recipe import training_set_commands
import yaml

logger = logging.getLogger(__name__)

#: A sequence directory holding this file is finished.
_SEQUENCE_DONE: Final = Path('samples') / 'meta.json'
#: Folder of a synthetic sequence's bag (the recipe keeps the training samples only).
_BAG_DIR: Final = 'bag'


class _Steps:
    """Runs (or, dry, prints) commands; a failed command raises InfiniHandError."""

    def __init__(self, jobs: int, dry_run: bool) -> None:
        self.jobs = jobs
        self.dry_run = dry_run

    def run(self, commands: Sequence[list[str]], quiet: bool = False) -> None:
        """Run ``commands``, ``jobs`` at a time (stdout dropped when ``quiet``)."""
        if self.dry_run:
            for command in commands:
                print(shlex.join(command))
            return
        pending, running, failed = list(commands), [], []
        while pending or running:
            while pending and len(running) < self.jobs:
                command = pending.pop(0)
                running.append((command, subprocess.Popen(
                    command, stdout=subprocess.DEVNULL if quiet else None)))
            command, process = running.pop(0)
            if process.wait() != 0:
                failed.append(f'exit status {process.returncode}: {shlex.join(command)}')
        if failed:
            raise InfiniHandError(f'{len(failed)} command(s) failed; the first, '
                                  f'{failed[0]}')

    def report(self, command: list[str], report: Path) -> None:
        """Run ``command``, printing its output and writing it to ``report``."""
        if self.dry_run:
            print(f'{shlex.join(command)} > {report}')
            return
        with subprocess.Popen(command, stdout=subprocess.PIPE, text=True) as process, \
                report.open('w', encoding='utf-8') as sink:
            for line in process.stdout:
                sys.stdout.write(line)
                sink.write(line)
        if process.returncode != 0:
            raise InfiniHandError(f'exit status {process.returncode}: {shlex.join(command)}')


def make_data(recipe: Recipe, runs: Path, steps: _Steps) -> None:
    """Write the training and evaluation sequences not written yet."""
    for item in recipe.training_sets:
        logger.info('training set %s', item.name)
        steps.run(training_set_commands(item, runs), quiet=True)
    for item in recipe.eval_sets:
        logger.info('evaluation set %s', item.name)
        for seed, fps, directory in item.sequences(runs):
            if (directory / _SEQUENCE_DONE).is_file():
                continue
            if not steps.dry_run:
                shutil.rmtree(directory, ignore_errors=True)
            steps.run([eval_sequence_command(item, seed, fps, directory)], quiet=True)
            if not steps.dry_run:
                shutil.rmtree(directory / _BAG_DIR, ignore_errors=True)


def train_stages(recipe: Recipe, runs: Path, steps: _Steps) -> None:
    """Train every stage without a final model, in order."""
    for stage in recipe.stages:
        if (final_model(runs, stage.name) / WEIGHTS_FILE).is_file():
            continue
        logger.info('stage %s (%s, %d steps)', stage.name, stage.setting, stage.steps)
        if stage.init_input_size is not None and not steps.dry_run:
            write_resized_init(stage, runs)
        steps.run([train_command(recipe, stage, runs)])


def write_resized_init(stage: Stage, runs: Path) -> None:
    """Write ``stage``'s start: its init's final model with the input size changed."""
    target = Path(stage_init(stage, runs))
    if (target / WEIGHTS_FILE).is_file():
        return
    width, height = stage.init_input_size
    with atomic_directory(target, overwrite=True) as staging:
        shutil.copytree(final_model(runs, stage.init), staging)
        geometry = read_yaml(staging / GEOMETRY_FILE)
        geometry['geometry']['aggregator'].update(image_width=width, image_height=height)
        (staging / GEOMETRY_FILE).write_text(yaml.safe_dump(geometry, sort_keys=False),
                                             encoding='utf-8')


def export_and_evaluate(recipe: Recipe, runs: Path, steps: _Steps) -> None:
    """Export the last stage and run the evaluations."""
    logger.info('export to %s', runs / recipe.export.out)
    steps.run([export_command(recipe, runs)])
    for evaluation in recipe.evaluations:
        logger.info('evaluation %s', evaluation.name)
        steps.report(evaluation_command(recipe, evaluation, runs),
                     runs / f'{evaluation.name}.md')


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser."""
    parser = argparse.ArgumentParser(prog='python -m infinihand_ros.train.recipe_runner',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('recipe', type=Path, help='recipe YAML, e.g. '
                                                  'models/tiny_synthetic/recipe.yaml')
    parser.add_argument('--runs', type=Path, default=Path('runs'),
                        help='output folder of data, stages and evaluations (default: runs)')
    parser.add_argument('--jobs', type=int, default=2,
                        help='data-generation processes at a time (default: 2)')
    parser.add_argument('--dry-run', action='store_true',
                        help='print the commands of the steps still to do; run nothing')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    logging.basicConfig(level=logging.INFO, format='[recipe] %(message)s')
    args = build_parser().parse_args(argv)
    try:
        if args.jobs < 1:
            raise InfiniHandError(f'--jobs must be >= 1, got {args.jobs}')
        recipe = load_recipe(args.recipe)
        steps = _Steps(args.jobs, args.dry_run)
        if not args.dry_run:
            args.runs.mkdir(parents=True, exist_ok=True)
        make_data(recipe, args.runs, steps)
        train_stages(recipe, args.runs, steps)
        export_and_evaluate(recipe, args.runs, steps)
    except InfiniHandError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
