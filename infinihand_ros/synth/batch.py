"""Command line: many training sequences in one process, samples only.

``python -m infinihand_ros.synth.batch --out DIR --seeds FIRST LAST --frames N [--fps F
--width W --height H --hands both|left|right --config FILE]`` writes ``DIR/seed_<s>/samples/``
for every seed in FIRST..LAST: the same training samples ``python -m infinihand_ros.synth`` writes
for that seed, without the bag and the previews. One process starts once (the single-sequence
command spends about 5 s importing its bag writer, more than a short sequence takes), and each
sample directory appears atomically, so a seed whose samples exist is skipped and an interrupted
run continues where it stopped.
"""

import argparse
from dataclasses import replace
import logging
from pathlib import Path
import shutil
import sys
import time

from infinihand_ros.core.atomic_io import check_writable_location
from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import load_config
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.synth.sample_sink import SAMPLES_DIR
from infinihand_ros.synth.sample_sink import SampleSink
from infinihand_ros.synth.sequence import HAND_CHOICES
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence


def build_parser() -> argparse.ArgumentParser:
    """Arguments (defaults of the optional settings come from config/synth.yaml)."""
    parser = argparse.ArgumentParser(
        prog='python -m infinihand_ros.synth.batch',
        description='Generate the training samples of many synthetic sequences, one per seed, '
                    'in one process; seeds already written are skipped.')
    parser.add_argument('--out', required=True, type=Path,
                        help='output directory; seed S goes to OUT/seed_S/samples')
    parser.add_argument('--seeds', required=True, type=int, nargs=2, metavar=('FIRST', 'LAST'),
                        help='inclusive seed range (non-negative)')
    parser.add_argument('--frames', required=True, type=int, help='frames per sequence')
    parser.add_argument('--fps', type=float, help='frame rate in Hz (default 10)')
    parser.add_argument('--width', type=int, help='image width in px (default 518)')
    parser.add_argument('--height', type=int, help='image height in px (default 378)')
    parser.add_argument('--hands', choices=sorted(HAND_CHOICES), help='hands shown (default both)')
    parser.add_argument('--config', type=Path, help='settings file (default: config/synth.yaml)')
    return parser


def resolve_config(args: argparse.Namespace) -> SynthConfig:
    """Check the arguments and return the sequence settings (InfiniHandError naming them)."""
    first, last = args.seeds
    if not 0 <= first <= last:
        raise InfiniHandError(f'--seeds: expected 0 <= FIRST <= LAST, got {first} {last}')
    if args.frames < 1:
        raise InfiniHandError(f'--frames must be at least 1, got {args.frames}')
    if args.out.exists() and not args.out.is_dir():
        raise InfiniHandError(f'--out {args.out} is not a directory')
    check_writable_location(args.out, '--out')
    config = load_config(args.config or config_dir() / 'synth.yaml', 'synth', SynthConfig)
    overrides = {key: getattr(args, key) for key in ('fps', 'width', 'height', 'hands')
                 if getattr(args, key) is not None}
    return replace(config, **overrides)


def write_sequence(config: SynthConfig, seed: int, frames: int, out: Path) -> bool:
    """Write one seed's samples under ``out`` unless they exist; return whether it wrote."""
    if (out / SAMPLES_DIR).is_dir():
        return False
    shutil.rmtree(out, ignore_errors=True)  # what an interrupted run left behind
    sequence = SyntheticSequence(config, seed, frames)
    with SampleSink(out / SAMPLES_DIR, sequence.describe()) as samples:
        for frame in sequence:
            samples.add(frame)
    return True


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    logging.basicConfig(level=logging.INFO, format='%(levelname)s %(name)s: %(message)s')
    args = build_parser().parse_args(argv)
    try:
        config = resolve_config(args)
        first, last = args.seeds
        start, written = time.perf_counter(), 0
        for seed in range(first, last + 1):
            written += write_sequence(config, seed, args.frames, args.out / f'seed_{seed}')
    except InfiniHandError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:
        print(f'error: writing --out {args.out} failed: {exc}', file=sys.stderr)
        return 1
    print(f'wrote {written} of {last - first + 1} sequences to {args.out} in '
          f'{time.perf_counter() - start:.1f} s ({last - first + 1 - written} already there)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
