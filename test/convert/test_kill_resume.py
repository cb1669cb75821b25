"""SIGKILL during a multi-input run, then the same command: the uninterrupted run's dataset."""

import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from convert_builders import BASE_NS
from convert_builders import fast_config
from convert_builders import image_bag
from convert_builders import PERIOD_NS
from infinihand_ros.convert.dataset_content import dataset_content
from infinihand_ros.convert.lerobot_layout import INFO_PATH
import numpy as np
import pytest

KILL_WAIT_S = 120.0


def _bag(path: Path, size: tuple[int, int], count: int, period_ns: int, seed: int) -> Path:
    rng = np.random.default_rng(seed)
    return image_bag(path, [(BASE_NS + k * period_ns, 'rgb8',
                             rng.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8))
                            for k in range(count)])


def _command(inputs: list[Path], output: Path, config: Path) -> list[str]:
    return [sys.executable, '-m', 'infinihand_ros.convert', *map(str, inputs), '--output',
            str(output), '--config', str(config), '--quiet', '--no-estimates-bag']


def _episodes(output: Path) -> int:
    try:
        return json.loads((output / INFO_PATH).read_text())['total_episodes']
    except (OSError, ValueError):
        return 0


@pytest.mark.slow
def test_sigkill_after_the_first_episode_then_rerun_matches(tmp_path: Path) -> None:
    inputs = [_bag(tmp_path / 'a', (160, 120), 4, PERIOD_NS, 1),
              _bag(tmp_path / 'b', (200, 100), 8, PERIOD_NS // 2, 2),
              _bag(tmp_path / 'c', (160, 120), 4, PERIOD_NS, 3)]
    config = fast_config(tmp_path / 'convert.yaml')
    reference = tmp_path / 'reference'
    subprocess.run(_command(inputs, reference, config), check=True, capture_output=True)
    killed = tmp_path / 'killed'
    process = subprocess.Popen(_command(inputs, killed, config), stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + KILL_WAIT_S
    while _episodes(killed) < 1 and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    assert process.returncode == -signal.SIGKILL, 'the run finished before it was killed'
    assert 1 <= _episodes(killed) < 3
    subprocess.run(_command(inputs, killed, config), check=True, capture_output=True)
    expected, got = dataset_content(reference), dataset_content(killed)
    assert sorted(got) == sorted(expected)
    for path, content in expected.items():
        assert got[path] == content, path
