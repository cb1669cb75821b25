"""bag_to_dataset under SIGKILL: kill a multi-input run at random times, re-run, compare.

Three synthetic inputs of different sizes and rates (160x120 at 10 Hz, 200x150 at 15 Hz,
224x168 at 10 Hz) are converted once without interruption; then each trial starts the same
command, SIGKILLs it after a random time within the uninterrupted run's wall time, runs the
command again to the end and compares the dataset with the uninterrupted one
(``convert.dataset_content``: data and meta by value, card and videos byte for byte).

    python benchmarks/convert_kill.py [--trials 10] [--seed 0] [--ba]
"""

import argparse
import json
import os
from pathlib import Path
import random
import signal
import subprocess
import sys
import tempfile
import time

from infinihand_ros.convert.dataset_content import dataset_content
from infinihand_ros.convert.lerobot_layout import INFO_PATH

INPUTS = (('a', 160, 120, 10, 12), ('b', 200, 150, 15, 18), ('c', 224, 168, 10, 12))


def _make_inputs(root: Path) -> list[Path]:
    bags = []
    for name, width, height, fps, frames in INPUTS:
        subprocess.run([sys.executable, '-m', 'infinihand_ros.synth', '--out', str(root / name),
                        '--seed', str(len(bags) + 1), '--frames', str(frames), '--fps',
                        str(fps), '--width', str(width), '--height', str(height)],
                       check=True, capture_output=True)
        bags.append(root / name / 'bag')
    return bags


def _command(inputs: list[Path], output: Path, ba: bool) -> list[str]:
    return [sys.executable, '-m', 'infinihand_ros.convert', *map(str, inputs), '--output',
            str(output), '--quiet', '--no-estimates-bag'] + ([] if ba else ['--no-ba'])


def _episodes(output: Path) -> int:
    try:
        return json.loads((output / INFO_PATH).read_text())['total_episodes']
    except (OSError, ValueError):
        return 0


def main() -> None:
    """Run the trials and print one line each and a summary."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--trials', type=int, default=10)
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--ba', action='store_true', help='bundle adjustment on')
    args = parser.parse_args()
    rng = random.Random(args.seed)
    with tempfile.TemporaryDirectory() as temp:
        root = Path(temp)
        inputs = _make_inputs(root)
        start = time.perf_counter()
        subprocess.run(_command(inputs, root / 'reference', args.ba), check=True,
                       capture_output=True)
        wall_s = time.perf_counter() - start
        expected = dataset_content(root / 'reference')
        print(f'uninterrupted run: {wall_s:.1f} s, {_episodes(root / "reference")} episodes')
        identical = 0
        for trial in range(args.trials):
            output = root / f'trial-{trial}'
            kill_after_s = rng.uniform(0.05, 0.95) * wall_s
            process = subprocess.Popen(_command(inputs, output, args.ba),
                                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            time.sleep(kill_after_s)
            finished = process.poll() is not None
            if not finished:
                os.kill(process.pid, signal.SIGKILL)
            process.wait()
            at_kill = _episodes(output)
            subprocess.run(_command(inputs, output, args.ba), check=True, capture_output=True)
            got = dataset_content(output)
            differ = sorted(path for path in set(got) | set(expected)
                            if got.get(path) != expected.get(path))
            identical += not differ
            print(f'trial {trial}: SIGKILL after {kill_after_s:.1f} s '
                  f'({"already finished" if finished else f"{at_kill} episodes in"}), '
                  f're-run identical: {not differ}' + (f' (differ: {differ})' if differ else ''))
        print(f'{identical}/{args.trials} re-runs identical to the uninterrupted run')


if __name__ == '__main__':
    main()
