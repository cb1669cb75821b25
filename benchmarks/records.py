"""Benchmark records: a benchmark's headline figures as one JSON file, with how they were made.

A benchmark run with ``--record PATH`` writes a record::

    {"benchmark": "profile_engine",
     "command": "python benchmarks/profile_engine.py --frames 60 --record ...",
     "machine": "x86_64, Intel(R) Xeon(R) ..., 2 CPUs, Linux 6.8",
     "commit": "f3e4320", "date": "2026-12-07", "load_average": 2.1,
     "figures": [{"name": "per-frame engine", "value": 9.1, "unit": "frames/s"}, ...]}

``load_average`` is the machine's 1-minute load average when the record was written (the
benchmark's own threads included): on a shared machine, a load above its CPU count means the
figures were measured while other work competed for the CPUs. Records live in
``benchmarks/results/``; ``benchmarks/figures.py`` builds the table in
``benchmarks/README.md`` from them, so no figure is typed by hand.
"""

import argparse
from dataclasses import asdict
from dataclasses import dataclass
import datetime
import json
import os
from pathlib import Path
import platform
import shlex
import subprocess
import sys

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / 'benchmarks' / 'results'
RECORD_KEYS = ('benchmark', 'command', 'machine', 'commit', 'date', 'load_average', 'figures')


@dataclass(frozen=True)
class Figure:
    """One measured figure.

    Attributes:
        name: what was measured, e.g. 'per-frame engine, sample bag'.
        value: the figure, in ``unit``.
        unit: e.g. 'frames/s', 'ms/frame', 'mm', '%'.

    """

    name: str
    value: float
    unit: str


def add_record_option(parser: argparse.ArgumentParser) -> None:
    """Add ``--record PATH`` to a benchmark's command line."""
    parser.add_argument('--record', type=Path, default=None, metavar='PATH',
                        help='also write the headline figures as a JSON record to PATH '
                        '(benchmarks/results/*.json feed benchmarks/README.md)')


def machine() -> str:
    """Return a one-line description of this machine: architecture, CPU model, CPUs, OS."""
    model = platform.processor()
    cpuinfo = Path('/proc/cpuinfo')
    if cpuinfo.is_file():
        for line in cpuinfo.read_text(encoding='utf-8', errors='replace').splitlines():
            if line.startswith('model name'):
                model = line.split(':', 1)[1].strip()
                break
    parts = [platform.machine(), model, f'{os.cpu_count()} CPUs',
             f'{platform.system()} {platform.release()}']
    return ', '.join(part for part in parts if part)


def commit() -> str:
    """Return the checkout's short commit, ``-dirty`` when tracked files other than pages differ.

    Changed markdown pages (the README, docs, model cards) do not change a figure, so they do
    not count; changed code, settings or data do.
    """
    def git(*args: str) -> str:
        return subprocess.run(['git', *args], cwd=ROOT, capture_output=True, text=True,
                              check=False).stdout.strip()
    head = git('rev-parse', '--short', 'HEAD') or 'unknown'
    changed = git('status', '--porcelain', '--untracked-files=no', '--', '.', ':(exclude)*.md')
    return head + ('-dirty' if changed else '')


def command_line() -> str:
    """Return the command that ran this process, as a user would type it from the root."""
    script = Path(sys.argv[0]).resolve()
    try:
        script = script.relative_to(ROOT)
    except ValueError:
        pass
    return shlex.join(['python', str(script), *sys.argv[1:]])


def record(benchmark: str, figures: list[Figure]) -> dict:
    """Return the record of this run's ``figures``."""
    return {'benchmark': benchmark, 'command': command_line(), 'machine': machine(),
            'commit': commit(), 'date': datetime.date.today().isoformat(),
            'load_average': round(os.getloadavg()[0], 1),
            'figures': [asdict(figure) for figure in figures]}


def write_record(path: Path | None, benchmark: str, figures: list[Figure]) -> None:
    """Write this run's record to ``path`` (nothing when ``path`` is None).

    Raises:
        ValueError: a figure's value is not a finite number.

    """
    if path is None:
        return
    for figure in figures:
        if not isinstance(figure.value, (int, float)) or figure.value != figure.value:
            raise ValueError(f'figure {figure.name!r} of {benchmark}: value {figure.value!r} '
                             'is not a finite number')
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record(benchmark, figures), indent=1) + '\n', encoding='utf-8')
