"""The package's installed executables as subprocesses on a private DDS graph (no rclpy).

Each run gets its own ``ROS_DOMAIN_ID`` and localhost-only discovery, so parallel runs and CI
never see each other's nodes. Processes write stdout and stderr to a log file, which callers
poll for a node's ready line; SIGINT ends them as Ctrl-C does.
"""

from collections.abc import Iterator
import contextlib
import itertools
import os
from pathlib import Path
import signal
import subprocess
import time
from typing import Final

from infinihand_ros.core.errors import InfiniHandError

PACKAGE_NAME: Final = 'infinihand_ros'
#: How often a log is read while waiting, s.
POLL_S: Final = 0.2
_DOMAINS = itertools.count()


def fresh_domain_id() -> int:
    """Return a DDS domain id (1..100) not used by an earlier call in this process."""
    return (os.getpid() + 37 * next(_DOMAINS)) % 100 + 1


def ros_env(domain_id: int) -> dict[str, str]:
    """Return this environment on ``domain_id`` with localhost-only discovery."""
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               OMP_NUM_THREADS='1')
    return env


def package_executable(name: str) -> Path:
    """Return the installed ``lib/infinihand_ros/<name>`` (where ``ros2 run`` looks).

    Raises:
        InfiniHandError: naming the executable when the package is not built or not on
            ``AMENT_PREFIX_PATH``.

    """
    try:
        from ament_index_python.packages import get_package_prefix
        from ament_index_python.packages import PackageNotFoundError
    except ImportError as exc:
        raise InfiniHandError('ament_index_python is not importable; source scripts/env.sh'
                              ) from exc
    try:
        path = Path(get_package_prefix(PACKAGE_NAME)) / 'lib' / PACKAGE_NAME / name
    except PackageNotFoundError as exc:
        raise InfiniHandError(f'{PACKAGE_NAME} is not on AMENT_PREFIX_PATH; build it with '
                              'colcon (make build) and source scripts/env.sh') from exc
    if not path.is_file():
        raise InfiniHandError(f'{path} is missing; rebuild with colcon (make build)')
    return path


def start(command: list[str], env: dict[str, str], log: Path) -> subprocess.Popen:
    """Start ``command`` with stdout and stderr to ``log``."""
    with open(log, 'wb') as out:
        return subprocess.Popen(command, env=env, stdout=out, stderr=subprocess.STDOUT)


def interrupt(process: subprocess.Popen, timeout_s: float = 60.0,
              signal_number: int = signal.SIGINT) -> int:
    """Send SIGINT (or ``signal_number``) and return the exit code."""
    process.send_signal(signal_number)
    return process.wait(timeout_s)


@contextlib.contextmanager
def running(command: list[str], env: dict[str, str], log: Path
            ) -> Iterator[subprocess.Popen]:
    """Run ``command`` for the with-block; kill it if the block left it running."""
    process = start(command, env, log)
    try:
        yield process
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(10)


def wait_for_count(log: Path, text: str, count: int, process: subprocess.Popen,
                   timeout_s: float) -> bool:
    """Wait until ``text`` appears ``count`` times in ``log`` (False on timeout or exit)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if log.read_text(errors='replace').count(text) >= count:
            return True
        if process.poll() is not None:
            return False
        time.sleep(POLL_S)
    return False


def wait_for_text(log: Path, text: str, process: subprocess.Popen, timeout_s: float) -> bool:
    """Wait until ``text`` appears in ``log`` (False on timeout or when the process ended)."""
    return wait_for_count(log, text, 1, process, timeout_s)
