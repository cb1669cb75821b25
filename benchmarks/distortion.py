"""Does honouring lens distortion pay? The same synthetic sequences with and without a lens.

    python benchmarks/distortion.py [--seeds 1 2] [--frames 60] [--width 320 --height 240]
        [--lenses plumb_bob:-0.25,0.08,0,0,0 equidistant:0.12,-0.03,0.01,-0.004]
        [--checkpoint models/tiny_synthetic] [--mode per_frame|windowed] [--out DIR] [--json]

For each seed the generator (``python -m infinihand_ros.synth``) draws one scene, motion and K
and renders it through a pinhole camera and through each lens (``--distortion``). The
evaluation (``python -m infinihand_ros.eval``, one run over every sequence) then scores:

- ``pinhole``: the undistorted sequences;
- ``<lens>``: the distorted ones with their lens given (the engine rectifies each frame);
- ``<lens> ignored``: the same images with the lens dropped from the sequence's metadata (what
  every consumer did before: K alone, as if the camera were pinhole).

It prints W-MPJPE (mm) and ATE (m) per condition, each the mean of the sequences' own figures.
Expected: a given lens within about 5 % of the pinhole figures, an ignored one worse. Figures
only; nothing is asserted. Measured with the defaults (CPU, per_frame): W-MPJPE / ATE pinhole
47.9 mm / 0.0133 m; plumb_bob given 48.2 / 0.0120 (+0.6 %, -10 %), ignored 83.4 / 0.0226
(+74 %, +69 %); equidistant given 50.4 / 0.0133 (+5.1 %, -0.2 %), ignored 86.8 / 0.0229
(+81 %, +71 %). Two seeds only: a few percent either way is noise.
"""

import argparse
import json
import os
from pathlib import Path
import subprocess
import sys
import tempfile

from infinihand_ros.corpus import sample_format as fmt
from infinihand_ros.synth.sample_sink import SAMPLES_DIR
import numpy as np

PINHOLE = 'pinhole'
IGNORED = 'ignored'
DEFAULT_LENSES = ('plumb_bob:-0.25,0.08,0,0,0', 'equidistant:0.12,-0.03,0.01,-0.004')
METRICS = ('W-MPJPE', 'ATE')


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seeds', type=int, nargs='+', default=[1, 2])
    parser.add_argument('--frames', type=int, default=60)
    parser.add_argument('--width', type=int, default=320)
    parser.add_argument('--height', type=int, default=240)
    parser.add_argument('--lenses', nargs='+', default=list(DEFAULT_LENSES),
                        help='MODEL:COEFFS of each lens (as the generator takes them)')
    parser.add_argument('--checkpoint', default='models/tiny_synthetic')
    parser.add_argument('--mode', choices=('per_frame', 'windowed'),
                        help="engine mode (default: the engine config's)")
    parser.add_argument('--out', type=Path, help='where the sequences go (default: a temporary '
                        'directory, removed afterwards)')
    parser.add_argument('--json', action='store_true', help='print one JSON line as well')
    return parser


def _lens_name(lens: str) -> str:
    return lens.split(':', 1)[0]


def _generate(out: Path, seed: int, args: argparse.Namespace, lens: str | None) -> None:
    """Run the generator for one sequence."""
    command = [sys.executable, '-m', 'infinihand_ros.synth', '--out', str(out), '--seed',
               str(seed), '--frames', str(args.frames), '--width', str(args.width), '--height',
               str(args.height)]
    if lens is not None:
        command += ['--distortion', lens]
    subprocess.run(command, check=True, capture_output=True, text=True)


def _without_lens(distorted: Path, out: Path) -> None:
    """Make ``out`` the distorted sequence with its lens dropped from ``meta.json``."""
    source, target = distorted / SAMPLES_DIR, out / SAMPLES_DIR
    target.mkdir(parents=True)
    for entry in source.iterdir():
        if entry.name != fmt.META_FILE:
            os.symlink(entry.resolve(), target / entry.name)
    meta = fmt.read_meta(source)
    meta['sequence'].update(distortion_model=None, distortion=[])
    (target / fmt.META_FILE).write_text(json.dumps(meta, indent=2), encoding='utf-8')


def make_sequences(root: Path, args: argparse.Namespace) -> dict[str, list[Path]]:
    """Generate every sequence under ``root``; return the sequence folders per condition."""
    conditions: dict[str, list[Path]] = {PINHOLE: []}
    for seed in args.seeds:
        pinhole = root / f's{seed}_{PINHOLE}'
        _generate(pinhole, seed, args, None)
        conditions[PINHOLE].append(pinhole)
        for lens in args.lenses:
            name = _lens_name(lens)
            distorted = root / f's{seed}_{name}'
            _generate(distorted, seed, args, lens)
            ignored = root / f's{seed}_{name}_{IGNORED}'
            _without_lens(distorted, ignored)
            conditions.setdefault(name, []).append(distorted)
            conditions.setdefault(f'{name} {IGNORED}', []).append(ignored)
    return conditions


def evaluate(conditions: dict[str, list[Path]], args: argparse.Namespace) -> dict[str, dict]:
    """Run the evaluation once over every sequence; return the mean figures per condition."""
    paths = [str(path) for paths in conditions.values() for path in paths]
    command = [sys.executable, '-m', 'infinihand_ros.eval', '--checkpoint', args.checkpoint,
               '--sequences', *paths, '--json']
    if args.mode is not None:
        command += ['--set', f'mode={args.mode}']
    run = subprocess.run(command, check=True, capture_output=True, text=True)
    report = json.loads(run.stdout.strip().splitlines()[-1])
    by_name = {item['name']: item['ours'] for item in report['sequences']}
    return {condition: {metric: float(np.mean([by_name[path.name][metric] for path in paths]))
                        for metric in METRICS}
            for condition, paths in conditions.items()}


def table(figures: dict[str, dict]) -> str:
    """Return the figures as a markdown table, with each condition against the pinhole one."""
    base = figures[PINHOLE]
    lines = ['| condition | W-MPJPE (mm) | vs pinhole | ATE (m) | vs pinhole |',
             '|---|---|---|---|---|']
    for condition, values in figures.items():
        changes = [100.0 * (values[m] / base[m] - 1.0) for m in METRICS]
        lines.append(f"| {condition} | {values['W-MPJPE']:.1f} | {changes[0]:+.1f} % | "
                     f"{values['ATE']:.4f} | {changes[1]:+.1f} % |")
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Generate, evaluate, print; return the exit code."""
    args = build_parser().parse_args(argv)
    if args.frames < 2 or not args.seeds:
        print(f'--frames must be at least 2 and --seeds non-empty, got {args.frames}, '
              f'{args.seeds}', file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix='distortion_') as temporary:
        root = args.out or Path(temporary)
        conditions = make_sequences(root, args)
        figures = evaluate(conditions, args)
    print(f'{len(args.seeds)} seed(s) x {args.frames} frames at {args.width}x{args.height}, '
          f'checkpoint {args.checkpoint}:')
    print(table(figures))
    if args.json:
        print(json.dumps(figures))
    return 0


if __name__ == '__main__':
    sys.exit(main())
