"""torchrun + DistributedDataParallel on the CPU (gloo): two replicas stay identical."""

from collections.abc import Callable
import json
import os
from pathlib import Path
import signal
import subprocess
import sys

from infinihand_ros.train.train_state import CHECKPOINTS_DIR
from infinihand_ros.train.trainer import SUMMARY_FILE
import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_two_processes_keep_identical_replicas(write_run_config: Callable[..., Path],
                                               tmp_path: Path) -> None:
    config = write_run_config(steps=3, checkpoint_every=2)
    output = tmp_path / 'ddp'
    environment = {**os.environ, 'OMP_NUM_THREADS': '1'}
    command = [sys.executable, '-m', 'torch.distributed.run', '--standalone',
               '--nproc-per-node', '2', '-m', 'infinihand_ros.train', '--config', str(config),
               '--output', str(output), '--no-progress']
    launcher = subprocess.Popen(command, cwd=ROOT, env=environment, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        stdout, stderr = launcher.communicate(timeout=180)
    except subprocess.TimeoutExpired:
        os.killpg(launcher.pid, signal.SIGKILL)  # torchrun and both workers
        stdout, stderr = launcher.communicate()
        pytest.fail(f'torchrun did not finish in 180 s:\n{stderr[-4000:]}')
    assert launcher.returncode == 0, stderr[-4000:]
    summary = json.loads((output / SUMMARY_FILE).read_text())
    assert summary['processes'] == 2 and summary['last_step'] == 3
    first, second = summary['replica_checksums']
    assert first == second
    assert sorted(path.name for path in (output / CHECKPOINTS_DIR).iterdir()) == [
        'final', 'step_0000002']
    assert stdout.count('trained steps 1..3') == 1  # rank 0 reports, alone
