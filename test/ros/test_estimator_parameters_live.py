"""Start-up of the installed estimator with wrong parameters: exit 1 naming the parameter."""

from pathlib import Path
import subprocess

from infinihand_ros.tools.node_processes import fresh_domain_id
from infinihand_ros.tools.node_processes import ros_env
from live_processes import LIB
from live_processes import SHARE
import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
pytest.importorskip('rclpy', reason='rclpy is not importable (source scripts/env.sh)')


def run_estimator(args: list[str]) -> subprocess.CompletedProcess:
    """Run the estimator with ``--ros-args`` and return what it did (it should stop)."""
    executable = LIB / 'estimator'
    if not executable.exists():
        pytest.skip(f'{executable} is not built (colcon build --symlink-install)')
    return subprocess.run([str(executable), '--ros-args', *args], env=ros_env(fresh_domain_id()),
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize('override,name', [
    ('smoothing.mode:=kalman', 'smoothing.mode'),
    ('smoothing.beta:=-1.0', 'smoothing.beta'),
    ('outputs.path_length:=ten', 'outputs.path_length'),
    ('engine.profile:=lab', 'engine.profile'),
    ("engine.set:='geometry_interval=0'", 'geometry_interval'),
])
def test_bad_parameter_stops_the_node_naming_it(override: str, name: str) -> None:
    """A bad -p value: exit code 1 and an error line naming the parameter."""
    done = run_estimator(['-p', override])
    assert done.returncode == 1, done.stderr
    assert name in done.stderr and 'cannot start' in done.stderr


def test_bad_params_file_value_stops_the_node(tmp_path: Path) -> None:
    """A params file with an int for a double parameter is refused at start-up."""
    params = tmp_path / 'bad.yaml'
    params.write_text('infinihand_estimator:\n  ros__parameters:\n    smoothing:\n'
                      '      min_cutoff_hz: 20\n')
    done = run_estimator(['--params-file', str(params)])
    assert done.returncode == 1
    assert 'smoothing.min_cutoff_hz' in done.stderr


def test_renamed_node_gets_the_shipped_params_file(tmp_path: Path) -> None:
    """The shipped file (keyed /**) reaches a node renamed with __node:=; a bad value stops it."""
    shipped = (SHARE / 'config' / 'estimator.yaml').read_text()
    assert 'profile: live\n' in shipped
    params = tmp_path / 'estimator.yaml'
    params.write_text(shipped.replace('profile: live\n', 'profile: lab\n'))
    done = run_estimator(['-r', '__node:=renamed_estimator', '--params-file', str(params)])
    assert done.returncode == 1, done.stderr
    assert 'engine.profile' in done.stderr and 'cannot start' in done.stderr
