"""Helpers of the live tests: the checkout's installed executables and the sample bag's topics."""

from collections.abc import Iterator
import contextlib
from pathlib import Path
import subprocess

from infinihand_ros.tools import node_processes

ROOT = Path(__file__).resolve().parents[2]
LIB = ROOT / 'install' / 'infinihand_ros' / 'lib' / 'infinihand_ros'
SHARE = ROOT / 'install' / 'infinihand_ros' / 'share' / 'infinihand_ros'
SAMPLE_BAG = ROOT / 'data' / 'sample_bag'
NODE = '/infinihand_estimator'
#: The node's standard QoS-override parameters: a reliable, deep image subscription, so that
#: every replayed frame reaches the node even on a loaded machine (sensor-data QoS may lose some).
LOSSLESS_INPUT = """/infinihand_estimator:
  ros__parameters:
    qos_overrides:
      /camera/image_raw/compressed:
        subscription:
          reliability: reliable
          history: keep_last
          depth: 200
"""
#: The sample bag's camera topics, remapped onto the node's relative inputs.
REMAPS = ('-r', 'image/compressed:=/camera/image_raw/compressed',
          '-r', 'camera_info:=/camera/camera_info')


def start(executable: str, args: list[str], env: dict[str, str], log: Path
          ) -> subprocess.Popen:
    """Start an installed executable of this checkout with stdout and stderr to ``log``."""
    return node_processes.start([str(LIB / executable), *args], env, log)


@contextlib.contextmanager
def running(executable: str, args: list[str], env: dict[str, str], log: Path
            ) -> Iterator[subprocess.Popen]:
    """Run an installed executable for the with-block; kill it if the block left it running."""
    with node_processes.running([str(LIB / executable), *args], env, log) as process:
        yield process
