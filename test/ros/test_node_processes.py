"""Subprocess helpers of the live runs (tools/node_processes.py)."""

from pathlib import Path
import sys

from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.tools.node_processes import fresh_domain_id
from infinihand_ros.tools.node_processes import package_executable
from infinihand_ros.tools.node_processes import ros_env
from infinihand_ros.tools.node_processes import running
from infinihand_ros.tools.node_processes import wait_for_text
from live_processes import LIB
import pytest


def test_ros_env_is_private_and_local() -> None:
    """The domain id and localhost discovery are set; the rest is this environment."""
    env = ros_env(42)
    assert (env['ROS_DOMAIN_ID'], env['ROS_AUTOMATIC_DISCOVERY_RANGE']) == ('42', 'LOCALHOST')
    assert env['PATH'] == ros_env(7)['PATH']


def test_fresh_domain_ids_differ_and_are_valid() -> None:
    """Consecutive calls give different ids in 1..100."""
    ids = [fresh_domain_id() for _ in range(3)]
    assert len(set(ids)) == 3 and all(1 <= i <= 100 for i in ids)


def test_package_executable_names_what_is_missing() -> None:
    """An installed executable resolves to lib/infinihand_ros; a missing one raises."""
    pytest.importorskip('ament_index_python')
    if not (LIB / 'estimator').exists():
        pytest.skip('the package is not built (colcon build --symlink-install)')
    assert package_executable('estimator').parent.name == 'infinihand_ros'
    with pytest.raises(InfiniHandError, match='no_such_tool is missing'):
        package_executable('no_such_tool')


def test_running_logs_output_and_kills_what_is_left(tmp_path: Path) -> None:
    """The log gets the output; a process still running after the block is killed."""
    log = tmp_path / 'sleeper.log'
    code = "import time; print('up', flush=True); time.sleep(60)"
    with running([sys.executable, '-c', code], ros_env(1), log) as process:
        assert wait_for_text(log, 'up', process, 30.0)
    assert process.returncode is not None
