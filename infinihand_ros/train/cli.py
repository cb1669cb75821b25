"""Command line of training: ``train`` (console script) or ``python -m infinihand_ros.train``.

``train --config CONFIG --output DIR [--set KEY=VALUE ...] [--resume CK] [--steps N]
[--stop-after N] [--init CK] [--data DIR ...] [--no-progress]`` trains one stage (the config's
``stage``) into DIR. CONFIG is a YAML path or a shipped name (``tiny``, ``tiny_stage2``,
``tiny_heads``, ``paper``, ``paper_stage2``: ``config/train_<name>.yaml``), possibly a
``base`` file plus overrides; ``--set train.batch_size=16`` replaces one value of it (dotted
key, YAML value). ``--resume`` continues from a checkpoint or from an output directory's
newest checkpoint, with that checkpoint's config unless ``--config`` is given.
Multi-GPU / multi-node: ``torchrun --nproc-per-node N -m infinihand_ros.train ...``.
"""

import argparse
import dataclasses
import logging
from pathlib import Path
import sys

from infinihand_ros.core.atomic_io import check_writable_location
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.train.config_compose import parse_override
from infinihand_ros.train.train_config import load_train_config
from infinihand_ros.train.train_config import TrainConfig
from infinihand_ros.train.train_state import CHECKPOINTS_DIR
from infinihand_ros.train.train_state import CONFIG_FILE
from infinihand_ros.train.train_state import find_checkpoint
from infinihand_ros.train.trainer import train

logger = logging.getLogger(__name__)


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``train``."""
    parser = argparse.ArgumentParser(
        prog='train', description='Train InfiniHand (Stage I or II, as the config says) on '
                                  'sequences in the training-sample form.')
    parser.add_argument('--config', help='training YAML file or shipped name (tiny, '
                                         'tiny_stage2, tiny_heads, paper, paper_stage2)')
    parser.add_argument('--set', nargs='+', action='extend', default=[], metavar='KEY=VALUE',
                        dest='overrides',
                        help='override one value of the config: a dotted key and a YAML '
                             'value, e.g. train.batch_size=16 losses.camera.weight=5.0')
    parser.add_argument('--output', type=Path,
                        help='output directory (log, curves, checkpoints); default: the '
                             "resumed run's")
    parser.add_argument('--resume', type=Path,
                        help='checkpoint directory, or an output directory (newest checkpoint)')
    parser.add_argument('--steps', type=int, help='override train.steps (schedule length)')
    parser.add_argument('--stop-after', type=int,
                        help='stop after this many steps of this call (train in chunks)')
    parser.add_argument('--init', help='override train.model.init_checkpoint (a whole-model '
                                       "checkpoint, e.g. Stage I's .../checkpoints/final/model)")
    parser.add_argument('--data', nargs='+', help='override train.data.sequences')
    parser.add_argument('--no-progress', action='store_true', help='hide the progress bar')
    return parser


def validate_args(args: argparse.Namespace) -> tuple[TrainConfig, Path]:
    """Check the arguments; return the resolved config and the output directory.

    Raises:
        InfiniHandError: naming the bad argument, the value and what is expected.

    """
    if args.config is None and args.resume is None:
        raise InfiniHandError('give --config (a new run) or --resume (continue a run)')
    checkpoint = find_checkpoint(args.resume) if args.resume is not None else None
    source = args.config if args.config is not None else checkpoint / CONFIG_FILE
    overrides = dict(parse_override(text) for text in args.overrides)
    config = load_train_config(source, overrides)
    for name in ('steps', 'stop_after'):
        value = getattr(args, name)
        if value is not None and value < 1:
            raise InfiniHandError(f'--{name.replace("_", "-")} must be >= 1, got {value}')
    if args.steps is not None:
        config = dataclasses.replace(config, steps=args.steps)
    if args.init is not None:
        if not Path(args.init).is_dir():
            raise InfiniHandError(f'--init {args.init}: no such checkpoint directory')
        config = dataclasses.replace(
            config, model=dataclasses.replace(config.model, init_checkpoint=args.init))
    if args.data is not None:
        config = dataclasses.replace(
            config, data=dataclasses.replace(config.data, sequences=tuple(args.data)))
    output = args.output
    if output is None:
        if checkpoint is None or checkpoint.parent.name != CHECKPOINTS_DIR:
            raise InfiniHandError('give --output (a new run writes there)')
        output = checkpoint.parent.parent
    if output.exists() and not output.is_dir():
        raise InfiniHandError(f'--output {output} exists and is not a directory')
    if args.resume is None and (output / CHECKPOINTS_DIR).is_dir():
        raise InfiniHandError(f'--output {output} already holds a run; continue it with '
                              f'--resume {output} or choose a new directory')
    check_writable_location(output, '--output')
    return config, output


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s')
    args = build_parser().parse_args(argv)
    try:
        config, output = validate_args(args)
        result = train(config, output, resume=args.resume, stop_after=args.stop_after,
                       progress=not args.no_progress)
    except InfiniHandError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:
        print(f'error: writing --output failed: {exc}', file=sys.stderr)
        return 1
    if result.rank != 0:
        return 0
    if result.losses:
        print(f'trained steps {result.first_step + 1}..{result.last_step} of {config.steps}: '
              f'loss {result.losses[0]:.4g} -> {result.losses[-1]:.4g}, '
              f'{result.seconds_per_step:.2f} s/step; checkpoint {result.checkpoint}')
    else:
        print(f'nothing to do: the run is at step {result.last_step} of {config.steps}')
    return 0
