"""Our installed commands load the package's Fast DDS profile when the user set none."""

from pathlib import Path
import time

from infinihand_ros.tools.node_processes import fresh_domain_id
from infinihand_ros.tools.node_processes import interrupt
from infinihand_ros.tools.node_processes import ros_env
from live_processes import LIB
from live_processes import running
import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
pytest.importorskip('rclpy', reason='rclpy is not importable (source scripts/env.sh)')

#: The profile's shared-memory segment is 16 MB; Fast DDS's default is about 0.5 MB.
LARGE_SEGMENT_BYTES = 16 * 2**20
STARTUP_S = 30.0


def _shm_segments(pid: int) -> list[int]:
    """Return the sizes of the Fast DDS shared-memory segments mapped by process ``pid``."""
    sizes = []
    for line in Path(f'/proc/{pid}/maps').read_text().splitlines():
        if '/dev/shm/fastrtps_' in line and '_port' not in line:
            low, high = (int(part, 16) for part in line.split()[0].split('-'))
            sizes.append(high - low)
    return sizes


def test_record_uses_the_large_segment_without_the_variable(tmp_path: Path) -> None:
    """The record command, started without a profile variable, maps a 16 MB SHM segment."""
    if not (LIB / 'record').exists():
        pytest.skip('the package is not built (colcon build --symlink-install)')
    env = ros_env(fresh_domain_id())
    env.pop('FASTRTPS_DEFAULT_PROFILES_FILE', None)
    env.pop('FASTDDS_DEFAULT_PROFILES_FILE', None)
    with running('record', ['-o', str(tmp_path / 'out'), '/unused'], env,
                 tmp_path / 'record.log') as recorder:
        deadline = time.monotonic() + STARTUP_S
        while (max(_shm_segments(recorder.pid), default=0) < LARGE_SEGMENT_BYTES
               and time.monotonic() < deadline):
            assert recorder.poll() is None, (tmp_path / 'record.log').read_text()
            time.sleep(0.5)
        sizes = _shm_segments(recorder.pid)
        assert interrupt(recorder) == 0
    assert max(sizes) >= LARGE_SEGMENT_BYTES, sizes
