"""The BA node live: killed mid-stream and restarted, the estimator never stops publishing.

Estimator (``engine.bundle_adjustment:=node``), BA node, recorder and replay run as separate
processes on a private DDS domain. The BA node uses a small pool (N=6, K=3) so that BA calls
come every few keyframes of the short sample bag, replayed at half speed.
"""

from pathlib import Path
import signal
import time

from infinihand_ros.bag.reader import BagReader
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.tools.node_processes import fresh_domain_id
from infinihand_ros.tools.node_processes import interrupt
from infinihand_ros.tools.node_processes import ros_env
from infinihand_ros.tools.node_processes import wait_for_count
from infinihand_ros.tools.node_processes import wait_for_text
from live_processes import LIB
from live_processes import NODE
from live_processes import REMAPS
from live_processes import running
from live_processes import SAMPLE_BAG
from live_processes import SHARE
from live_processes import start
import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
pytest.importorskip('rclpy', reason='rclpy is not importable (source scripts/env.sh)')

APPLIED = 'applied bundle-adjustment corrections'
LOST = 'bundle-adjustment node lost'
#: Keyframes reach BA at a steady rate, whatever this machine's load (a paced interval grows
#: with it, and BA sees only the frames the geometry branch runs on).
KEYFRAMES_STEADY = 'geometry_interval=3'
#: The estimator publishes at least every this many seconds while images come (5 Hz input).
MAX_OUTPUT_GAP_S = 2.0


@pytest.fixture(autouse=True)
def _installed() -> None:
    if not (LIB / 'bundle_adjustment').exists():
        pytest.skip('the package is not built (colcon build --symlink-install)')


def _statuses(bag: Path, suffix: str) -> list[tuple[int, dict[str, str], str, int]]:
    """Return (log time, values, message, level) of the recorded statuses named ``*suffix``."""
    out = []
    with BagReader(bag) as reader:
        for _, log_time, msg in reader.messages(['/diagnostics']):
            for status in msg.status:
                if status.name.endswith(suffix):
                    out.append((log_time, {kv.key: kv.value for kv in status.values},
                                status.message, int(status.level)))
    return out


def _pose_times(bag: Path) -> list[int]:
    """Return the receive times of the recorded camera poses, ns."""
    with BagReader(bag) as reader:
        return [log_time for _, log_time, _ in reader.messages([f'{NODE}/camera_pose'])]


def test_ba_node_killed_and_restarted_mid_stream(tmp_path: Path) -> None:
    """Refinement before the kill, WARN 'lost' during the outage, refinement after restart."""
    ba_yaml = tmp_path / 'ba.yaml'
    ba_yaml.write_text('ba:\n  pool:\n    trigger: 6\n    stride: 3\n')
    env = ros_env(fresh_domain_id())
    estimator_args = ['--ros-args', '--params-file', str(SHARE / 'config' / 'estimator.yaml'),
                      '-p', 'engine.bundle_adjustment:=node', '-p', 'ba_node.timeout_s:=2.0',
                      '-p', f"engine.set:='{KEYFRAMES_STEADY}'", *REMAPS]
    ba_args = ['--ros-args', '-p', f'config:={ba_yaml}']
    node_log, out = tmp_path / 'estimator.log', tmp_path / 'out'
    with running('estimator', estimator_args, env, node_log) as node, \
            running('bundle_adjustment', ba_args, env, tmp_path / 'ba1.log') as first, \
            running('record', ['-o', str(out), f'{NODE}/camera_pose', '/diagnostics',
                               '/bundle_adjustment/corrections'], env,
                    tmp_path / 'record.log') as recorder:
        assert wait_for_text(node_log, 'ready: engine', node, 120.0), node_log.read_text()
        assert wait_for_text(tmp_path / 'ba1.log', 'ready: pool', first, 120.0)
        # 3 Hz (50 s): frames still come after a restart that is slow on a loaded machine.
        replay = start('replay', [str(SAMPLE_BAG), '--rate', '0.3', '--wait-for-subscribers',
                                  '20', '--topics', '/camera/image_raw/compressed',
                                  '/camera/camera_info'], env, tmp_path / 'replay.log')
        assert wait_for_count(node_log, APPLIED, 1, node, 60.0), node_log.read_text()
        first.send_signal(signal.SIGKILL)
        first.wait(10)
        assert wait_for_text(node_log, LOST, node, 15.0), node_log.read_text()
        applied_before = node_log.read_text().count(APPLIED)
        with running('bundle_adjustment', ba_args, env, tmp_path / 'ba2.log') as second:
            assert wait_for_text(tmp_path / 'ba2.log', 'ready: pool', second, 120.0)
            assert wait_for_count(node_log, APPLIED, applied_before + 1, node, 60.0), \
                (tmp_path / 'ba2.log').read_text()
            assert replay.wait(120) == 0, (tmp_path / 'replay.log').read_text()
            time.sleep(3.0)  # the last frame's inference and a diagnostics period
            assert interrupt(node) == 0, node_log.read_text()
            assert interrupt(second) == 0, (tmp_path / 'ba2.log').read_text()
        assert interrupt(recorder) == 0
    times = _pose_times(out)
    assert len(times) >= 30
    gaps = [(b - a) / NS_PER_S for a, b in zip(times, times[1:])]
    assert max(gaps) < MAX_OUTPUT_GAP_S, 'the estimator stopped publishing'
    estimator = _statuses(out, ': estimator')
    lost = [(t, v) for t, v, message, level in estimator
            if v['ba_state'] == 'lost' and level == 1 and 'poses are unrefined' in message]
    assert lost, [v['ba_state'] for _, v, _, _ in estimator]
    lost_at, during = lost[0]
    assert int(during['ba_outages']) == 1 and int(during['ba_results_applied']) >= 1
    assert lost_at > times[0] and lost_at < times[-1], 'the outage fell outside the stream'
    after = [v for t, v, _, _ in estimator if t > lost_at and v['ba_state'] == 'connected']
    assert after and int(after[-1]['ba_results_applied']) > int(during['ba_results_applied'])
    # The node's own count went on through the outage (the recorder may miss a few under load).
    assert int(during['frames_published']) < int(after[0]['frames_published'])
    assert int(after[-1]['frames_published']) >= len(times)
    assert 'Traceback' not in node_log.read_text()
    assert _statuses(out, ': bundle adjustment'), 'the BA node reports on /diagnostics'
