"""Benchmark scripts: bad arguments refused with one line; the error-source placement."""

import importlib.util
from pathlib import Path
import subprocess
import sys

import numpy as np

BENCHMARKS = Path(__file__).resolve().parents[1] / 'benchmarks'


def test_throughput_refuses_fewer_than_three_frames() -> None:
    """--frames 2 exits 2 with argparse's one-line error naming the minimum."""
    run = subprocess.run([sys.executable, str(BENCHMARKS / 'throughput.py'), '--frames', '2'],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert '--frames must be at least 3, got 2' in run.stderr


def _error_sources():
    """Import benchmarks/eval_error_sources.py (a script, not a package module)."""
    spec = importlib.util.spec_from_file_location('eval_error_sources',
                                                  BENCHMARKS / 'eval_error_sources.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_error_sources_places_camera_joints_with_each_frames_pose() -> None:
    """place() applies frame t's camera-to-world pose; the angle of a 90 deg turn is 90."""
    sources = _error_sources()
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z
    T = np.stack([np.eye(4), np.eye(4)])
    T[1, :3, :3], T[1, :3, 3] = turn, [1.0, 2.0, 3.0]
    joints = np.zeros((2, 2, 21, 3))
    joints[..., 0] = 0.5  # every joint at x = 0.5 m in the camera frame
    world = sources.place(joints, T)
    np.testing.assert_allclose(world[0], joints[0])
    np.testing.assert_allclose(world[1], np.broadcast_to([1.0, 2.5, 3.0], (2, 21, 3)))
    np.testing.assert_allclose(sources.rotation_angle_deg(np.stack([np.eye(3), turn])),
                               [0.0, 90.0], atol=1e-9)
