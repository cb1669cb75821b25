"""Start-up of the installed BA node with wrong parameters: exit 1 naming the parameter."""

from pathlib import Path
import subprocess

from infinihand_ros.tools.node_processes import fresh_domain_id
from infinihand_ros.tools.node_processes import ros_env
from live_processes import LIB
import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
pytest.importorskip('rclpy', reason='rclpy is not importable (source scripts/env.sh)')


@pytest.mark.parametrize('override,name', [
    ('keyframes.max_pending:=0', 'keyframes.max_pending'),
    ('config:=/no/such/ba.yaml', 'config'),
    ('status_period_s:=fast', 'status_period_s'),
])
def test_bad_parameter_stops_the_ba_node_naming_it(override: str, name: str) -> None:
    """A bad -p value: exit code 1 and an error line naming the parameter."""
    executable = LIB / 'bundle_adjustment'
    if not executable.exists():
        pytest.skip(f'{executable} is not built (colcon build --symlink-install)')
    done = subprocess.run([str(executable), '--ros-args', '-p', override],
                          env=ros_env(fresh_domain_id()), capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 1, done.stderr
    assert f'parameter {name}' in done.stderr and 'cannot start' in done.stderr


def test_bad_ba_file_key_is_named(tmp_path: Path) -> None:
    """A BA YAML with an unknown key stops the node naming the key."""
    ba_yaml = tmp_path / 'ba.yaml'
    ba_yaml.write_text('ba:\n  pool:\n    triger: 6\n')
    done = subprocess.run([str(LIB / 'bundle_adjustment'), '--ros-args', '-p',
                           f'config:={ba_yaml}'], env=ros_env(fresh_domain_id()),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 1 and 'triger' in done.stderr
