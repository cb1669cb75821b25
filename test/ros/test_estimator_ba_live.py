"""The installed estimator with in-process BA: the worker lives and ends with it.

The shipped params file with ``engine.bundle_adjustment: in_process`` runs bundle adjustment in
the engine's worker process. The sample bag is
replayed in, so BA has selections to refine, and the node is stopped while BA is still busy:
SIGINT must end it with exit code 0 within the interrupt timeout and leave no process behind;
after SIGKILL (no clean-up at all) the worker processes must still end by themselves.
"""

from pathlib import Path
import signal
import subprocess
import time

from infinihand_ros.bag.reader import BagReader
from infinihand_ros.tools.node_processes import fresh_domain_id
from infinihand_ros.tools.node_processes import interrupt
from infinihand_ros.tools.node_processes import ros_env
from infinihand_ros.tools.node_processes import wait_for_text
from live_processes import LIB
from live_processes import REMAPS
from live_processes import running
from live_processes import SAMPLE_BAG
from live_processes import SHARE
from live_processes import start
import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
pytest.importorskip('rclpy', reason='rclpy is not importable (source scripts/env.sh)')

READY = 'ready: engine'
#: The BA worker's child (``python -m infinihand_ros.ba.process``), as its command line reads.
BA_CHILD = 'infinihand_ros.ba.process'
#: Seconds the worker processes may take to end: a BA call in progress finishes first.
WORKER_EXIT_S = 120.0
#: Keyframes reach BA at a steady rate, whatever this machine's load (a paced interval grows
#: with it, and BA sees only the frames the geometry branch runs on).
STEADY = 'geometry_interval=3'


@pytest.fixture(autouse=True)
def _installed() -> None:
    if not (LIB / 'estimator').exists():
        pytest.skip('the package is not built (colcon build --symlink-install)')


def _children(pid: int) -> dict[int, str]:
    """Return the child processes of ``pid`` and their command lines."""
    children = {}
    for proc in Path('/proc').iterdir():
        if not proc.name.isdigit():
            continue
        try:
            stat = (proc / 'stat').read_text()
            command = (proc / 'cmdline').read_bytes().replace(b'\0', b' ').decode()
        except OSError:  # ended meanwhile
            continue
        if int(stat.rsplit(')', 1)[1].split()[1]) == pid:
            children[int(proc.name)] = command
    return children


def _alive(pids: set[int]) -> set[int]:
    """Return the processes of ``pids`` that still run (zombies count as ended)."""
    alive = set()
    for pid in pids:
        try:
            state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
        except OSError:
            continue
        if state != 'Z':
            alive.add(pid)
    return alive


def _wait_until_ended(pids: set[int], timeout_s: float) -> set[int]:
    """Wait for ``pids`` to end; return those still running after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while _alive(pids) and time.monotonic() < deadline:
        time.sleep(0.2)
    return _alive(pids)


def _worker_processes(node: subprocess.Popen, timeout_s: float = 60.0) -> dict[int, str]:
    """Return the node's child processes once the BA worker's is among them."""
    deadline = time.monotonic() + timeout_s
    children = _children(node.pid)
    while not any(BA_CHILD in command for command in children.values()) \
            and time.monotonic() < deadline:
        time.sleep(0.2)
        children = _children(node.pid)
    return children


def _replay(env: dict[str, str], log: Path) -> None:
    """Replay the sample bag's camera topics at half speed (5 Hz).

    The node drops what it cannot take; at 5 Hz it takes enough of them, on a slow or loaded
    machine too, for its keyframe pool to select keyframes for BA.
    """
    replay = start('replay', [str(SAMPLE_BAG), '--rate', '0.5', '--wait-for-subscribers', '20',
                              '--delay', '1', '--topics', '/camera/image_raw/compressed',
                              '/camera/camera_info'], env, log)
    assert replay.wait(120) == 0, log.read_text()


def test_sigint_stops_the_ba_worker_with_the_node(tmp_path: Path) -> None:
    """BA in-process and busy; SIGINT: exit 0, no child left."""
    env = ros_env(fresh_domain_id())
    node_log, out = tmp_path / 'estimator.log', tmp_path / 'out'
    params = ['--params-file', str(SHARE / 'config' / 'estimator.yaml'),
              '-p', "engine.bundle_adjustment:='in_process'", '-p', f"engine.set:='{STEADY}'"]
    with running('estimator', ['--ros-args', *params, *REMAPS], env, node_log) as node, \
            running('record', ['-o', str(out), '/diagnostics'], env,
                    tmp_path / 'record.log') as recorder:
        assert wait_for_text(node_log, READY, node, 120.0), node_log.read_text()
        workers = _worker_processes(node)
        assert any(BA_CHILD in command for command in workers.values()), workers
        _replay(env, tmp_path / 'replay.log')
        time.sleep(2.0)  # a diagnostics period after the last frame
        assert interrupt(node) == 0, node_log.read_text()
        assert interrupt(recorder) == 0
    assert not _wait_until_ended(set(workers), 10.0), workers
    with BagReader(out) as reader:
        reports = [{kv.key: kv.value for kv in status.values}
                   for _, _, msg in reader.messages(['/diagnostics']) for status in msg.status
                   if status.name.endswith(': estimator')]
    states = [report['ba_state'] for report in reports]
    # A pool selection went to BA (a call may start and end between two diagnostics periods).
    assert int(reports[-1]['ba_calls_submitted']) > 0, reports[-1]
    assert not {'off', 'failed'} & set(states), states


def test_sigkill_leaves_no_ba_worker_behind(tmp_path: Path) -> None:
    """Killed with BA busy: the worker processes notice the closed pipe and end by themselves."""
    env = ros_env(fresh_domain_id())
    node_log = tmp_path / 'estimator.log'
    params = ['--params-file', str(SHARE / 'config' / 'estimator.yaml'),
              '-p', "engine.bundle_adjustment:='in_process'"]
    with running('estimator', ['--ros-args', *params, *REMAPS], env, node_log) as node:
        assert wait_for_text(node_log, READY, node, 120.0), node_log.read_text()
        workers = _worker_processes(node)
        assert any(BA_CHILD in command for command in workers.values()), workers
        _replay(env, tmp_path / 'replay.log')
        assert interrupt(node, signal_number=signal.SIGKILL) == -signal.SIGKILL
    assert not _wait_until_ended(set(workers), WORKER_EXIT_S), workers
