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


def _kill_workers(output: Path) -> list[int]:
    """Kill the processes whose command line names ``output`` (Linux /proc); return their ids."""
    killed = []
    for entry in Path('/proc').iterdir():
        try:
            cmdline = (entry / 'cmdline').read_bytes().replace(b'\0', b' ').decode()
        except (OSError, UnicodeDecodeError):
            continue
        if entry.name.isdigit() and str(output) in cmdline:
            try:
                os.kill(int(entry.name), signal.SIGKILL)
                killed.append(int(entry.name))
            except ProcessLookupError:
                pass
    return killed


@pytest.mark.slow
def test_two_processes_keep_identical_replicas(write_run_config: Callable[..., Path],
                                               tmp_path: Path) -> None:
    config = write_run_config(steps=3, checkpoint_every=2)
    output = tmp_path / 'ddp'
    environment = {**os.environ, 'OMP_NUM_THREADS': '1'}
    command = [sys.executable, '-m', 'torch.distributed.run', '--standalone',
               '--nproc-per-node', '2', '-m', 'infinihand_ros.train', '--config', str(config),
               '--output', str(output), '--no-progress']
    # Output goes to files, not pipes: a worker left behind cannot keep the test waiting.
    out_path, err_path = tmp_path / 'stdout.txt', tmp_path / 'stderr.txt'
    with out_path.open('w') as out, err_path.open('w') as err:
        launcher = subprocess.Popen(command, cwd=ROOT, env=environment, stdout=out, stderr=err,
                                    text=True, start_new_session=True)
        try:
            launcher.wait(timeout=180)
        except subprocess.TimeoutExpired:
            os.killpg(launcher.pid, signal.SIGKILL)  # torchrun
            launcher.wait()
        finally:
            _kill_workers(output)  # torchrun starts its workers in sessions of their own
    stdout, stderr = out_path.read_text(), err_path.read_text()
    assert launcher.returncode == 0, stderr[-4000:]
    summary = json.loads((output / SUMMARY_FILE).read_text())
    assert summary['processes'] == 2 and summary['last_step'] == 3
    first, second = summary['replica_checksums']
    assert first == second
    assert sorted(path.name for path in (output / CHECKPOINTS_DIR).iterdir()) == [
        'final', 'step_0000002']
    assert stdout.count('trained steps 1..3') == 1  # rank 0 reports, alone
