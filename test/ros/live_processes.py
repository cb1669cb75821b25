"""Helpers of the live tests: the installed executables as subprocesses on a private domain."""

from collections.abc import Iterator
import contextlib
import itertools
import os
from pathlib import Path
import signal
import subprocess
import time

ROOT = Path(__file__).resolve().parents[2]
LIB = ROOT / 'install' / 'infinihand_ros' / 'lib' / 'infinihand_ros'
SHARE = ROOT / 'install' / 'infinihand_ros' / 'share' / 'infinihand_ros'
SAMPLE_BAG = ROOT / 'data' / 'sample_bag'
NODE = '/infinihand_estimator'
#: The sample bag's camera topics, remapped onto the node's relative inputs.
REMAPS = ('-r', 'image/compressed:=/camera/image_raw/compressed',
          '-r', 'camera_info:=/camera/camera_info')
_DOMAINS = itertools.count()


def fresh_domain_id() -> int:
    """Return a DDS domain id (1..100) not used by an earlier test of this process."""
    return (os.getpid() + 37 * next(_DOMAINS)) % 100 + 1


def ros_env(domain_id: int) -> dict[str, str]:
    """Return this environment on ``domain_id`` with localhost-only discovery."""
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               OMP_NUM_THREADS='1')
    return env


def start(executable: str, args: list[str], env: dict[str, str], log: Path
          ) -> subprocess.Popen:
    """Start an installed executable with stdout and stderr to ``log``."""
    with open(log, 'wb') as out:
        return subprocess.Popen([str(LIB / executable), *args], env=env, stdout=out,
                                stderr=subprocess.STDOUT)


def interrupt(process: subprocess.Popen, timeout_s: float = 60.0,
              signal_number: int = signal.SIGINT) -> int:
    """Send SIGINT (or ``signal_number``) and return the exit code."""
    process.send_signal(signal_number)
    return process.wait(timeout_s)


@contextlib.contextmanager
def running(executable: str, args: list[str], env: dict[str, str], log: Path
            ) -> Iterator[subprocess.Popen]:
    """Run an executable for the with-block; kill it if the block left it running."""
    process = start(executable, args, env, log)
    try:
        yield process
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(10)


def wait_for_text(log: Path, text: str, process: subprocess.Popen, timeout_s: float) -> bool:
    """Wait until ``text`` appears in ``log`` (False on timeout or when the process ended)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if text in log.read_text(errors='replace'):
            return True
        if process.poll() is not None:
            return False
        time.sleep(0.2)
    return False


def wait_for_count(log: Path, text: str, count: int, process: subprocess.Popen,
                   timeout_s: float) -> bool:
    """Wait until ``text`` appears ``count`` times in ``log`` (False on timeout or exit)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if log.read_text(errors='replace').count(text) >= count:
            return True
        if process.poll() is not None:
            return False
        time.sleep(0.2)
    return False
