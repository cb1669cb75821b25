"""Benchmark scripts refuse bad arguments with one line before doing any work."""

from pathlib import Path
import subprocess
import sys

BENCHMARKS = Path(__file__).resolve().parents[1] / 'benchmarks'


def test_throughput_refuses_fewer_than_three_frames() -> None:
    """--frames 2 exits 2 with argparse's one-line error naming the minimum."""
    run = subprocess.run([sys.executable, str(BENCHMARKS / 'throughput.py'), '--frames', '2'],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert '--frames must be at least 3, got 2' in run.stderr
