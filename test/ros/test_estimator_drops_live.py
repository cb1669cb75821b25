"""The installed estimator fed faster than the model runs: drops are counted, nothing queues.

The sample bag is replayed as fast as publishing goes (``--rate 0``) into the estimator; the
image callback keeps only the newest frame, so most frames are dropped, and every frame the
node received is either published or counted as dropped.
"""

from pathlib import Path
import time

from infinihand_ros.bag.reader import BagReader
from infinihand_ros.tools.node_processes import fresh_domain_id
from infinihand_ros.tools.node_processes import interrupt
from infinihand_ros.tools.node_processes import ros_env
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


@pytest.fixture(autouse=True)
def _installed() -> None:
    if not (LIB / 'estimator').exists():
        pytest.skip('the package is not built (colcon build --symlink-install)')


def test_drops_are_counted_when_the_input_outruns_the_model(tmp_path: Path) -> None:
    """Replay at full speed: dropped > 0 and received == published + dropped."""
    env = ros_env(fresh_domain_id())
    node_log, out = tmp_path / 'estimator.log', tmp_path / 'out'
    params = ['--params-file', str(SHARE / 'config' / 'estimator.yaml')]
    with running('estimator', ['--ros-args', *params, *REMAPS], env, node_log) as node, \
            running('record', ['-o', str(out), f'{NODE}/camera_pose', '/diagnostics'], env,
                    tmp_path / 'record.log') as recorder:
        assert wait_for_text(node_log, 'ready: engine', node, 120.0), node_log.read_text()
        # The poses come within a second of the replay's start: the recorder must be subscribed.
        assert wait_for_text(tmp_path / 'record.log', f'recording {NODE}/camera_pose', recorder,
                             30.0), (tmp_path / 'record.log').read_text()
        replay = start('replay', [str(SAMPLE_BAG), '--rate', '0', '--wait-for-subscribers',
                                  '20', '--delay', '1', '--topics', '/camera/image_raw/compressed',
                                  '/camera/camera_info'], env, tmp_path / 'replay.log')
        assert replay.wait(120) == 0, (tmp_path / 'replay.log').read_text()
        time.sleep(4.0)  # the last frame's inference and a diagnostics period
        assert interrupt(node) == 0, node_log.read_text()
        assert interrupt(recorder) == 0
    with BagReader(out) as reader:
        published = sum(1 for _ in reader.messages([f'{NODE}/camera_pose']))
        statuses = [status for _, _, msg in reader.messages(['/diagnostics'])
                    for status in msg.status if status.name.endswith(': estimator')]
    values = {kv.key: kv.value for kv in statuses[-1].values}
    received, dropped = int(values['frames_received']), int(values['frames_dropped'])
    assert dropped > 0 and int(values['bad_frames']) == 0
    assert received == int(values['frames_published']) + dropped
    assert int(values['frames_published']) == published < received
    assert any('dropped (input faster than the model)' in status.message
               for status in statuses)
