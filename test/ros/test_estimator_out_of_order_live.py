"""The installed estimator skips images stamped no later than the last one it accepted.

Frames are accepted (until the engine's anchor frames are out), then a burst of late and
repeated stamps arrives, then a newer frame: the burst is counted in ``frames_out_of_order``
(not as dropped or bad), the throttled warning names the topic and both stamps once, and the
newer frame is still estimated.
"""

from pathlib import Path
import time

from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.tools.node_processes import fresh_domain_id
from infinihand_ros.tools.node_processes import interrupt
from infinihand_ros.tools.node_processes import ros_env
from infinihand_ros.tools.node_processes import wait_for_text
from live_processes import LIB
from live_processes import running
from live_processes import SAMPLE_BAG
import numpy as np
import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
rclpy = pytest.importorskip('rclpy', reason='rclpy is not importable (source scripts/env.sh)')
DiagnosticArray = pytest.importorskip('diagnostic_msgs.msg').DiagnosticArray
Image = pytest.importorskip('sensor_msgs.msg').Image
qos = pytest.importorskip('rclpy.qos')

READY = 'ready: engine'
NS_PER_S = 1_000_000_000
FIRST_NS = 100 * NS_PER_S
#: In-order frames sent at most before the engine's anchor frames must have come out.
MAX_ACCEPTED = 10
#: Frames stamped no later than the last accepted one: late, repeated, far older.
LATE = 20
WARNING = 'skipping an image stamped'
#: A reliable, deep image subscription: the burst reaches the node whole (the count is exact).
LOSSLESS_INPUT = """/infinihand_estimator:
  ros__parameters:
    qos_overrides:
      /image:
        subscription:
          reliability: reliable
          history: keep_last
          depth: 100
"""


@pytest.fixture(autouse=True)
def _installed() -> None:
    if not (LIB / 'estimator').exists():
        pytest.skip('the package is not built (colcon build --symlink-install)')


def _image(rgb: np.ndarray, stamp_ns: int) -> object:
    height, width = rgb.shape[:2]
    msg = Image(height=height, width=width, encoding='rgb8', step=width * 3, data=rgb.tobytes())
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, NS_PER_S)
    msg.header.frame_id = 'camera_optical_frame'
    return msg


class _Source:
    """A test node that publishes images to the estimator and reads its diagnostics."""

    def __init__(self, domain_id: int) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node('out_of_order_source', context=self.context)
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.values: dict[str, str] = {}
        self.messages: list[str] = []
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        self.images = self.node.create_publisher(
            Image, 'image', qos.QoSProfile(depth=100, reliability=qos.ReliabilityPolicy.RELIABLE))

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        self.values = {v.key: v.value for v in msg.status[0].values}
        self.messages.append(msg.status[0].message)

    def spin_until(self, condition, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not condition():
            self.executor.spin_once(timeout_sec=0.05)
        return condition()

    def count(self, key: str) -> int:
        return int(self.values.get(key, 0))

    def processed(self) -> int:
        """Return the frames the engine took (each counts under one intrinsics source)."""
        return sum(int(value) for key, value in self.values.items()
                   if key.startswith('intrinsics_from_'))

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def test_late_and_repeated_stamps_are_counted_and_skipped(tmp_path: Path) -> None:
    """20 stale stamps: frames_out_of_order 20, one warning, no bad frame; the node goes on."""
    frame = next(iter(read_camera_frames(SAMPLE_BAG)))
    rgb = np.ascontiguousarray(frame.rgb[::2, ::2])
    domain = fresh_domain_id()
    log, params = tmp_path / 'estimator.log', tmp_path / 'lossless_input.yaml'
    params.write_text(LOSSLESS_INPUT)
    with running('estimator', ['--ros-args', '--params-file', str(params)], ros_env(domain),
                 log) as node:
        assert wait_for_text(log, READY, node, 120.0), log.read_text()
        source = _Source(domain)
        try:
            assert source.spin_until(lambda: source.images.get_subscription_count() > 0, 60.0)
            accepted = []  # in order, each once the engine took the previous one
            while source.count('frames_published') == 0 and len(accepted) < MAX_ACCEPTED:
                accepted.append(FIRST_NS + len(accepted) * NS_PER_S)
                source.images.publish(_image(rgb, accepted[-1]))
                assert source.spin_until(lambda: source.processed() == len(accepted), 120.0), (
                    log.read_text())
            assert source.spin_until(lambda: source.count(
                'frames_published') == len(accepted), 120.0), log.read_text()
            last = accepted[-1]
            late = [last - 1, last, *(k * NS_PER_S for k in range(1, LATE - 1))]
            for stamp in late:  # back to back: none may replace a frame waiting in the node
                source.images.publish(_image(rgb, stamp))
            source.images.publish(_image(rgb, last + NS_PER_S))
            assert source.spin_until(lambda: source.count(
                'frames_published') == len(accepted) + 1, 120.0), log.read_text()
            source.spin_until(lambda: False, 1.5)  # one more diagnostics period
        finally:
            source.close()
        assert node.poll() is None, log.read_text()
        assert interrupt(node) == 0
    values = source.values
    assert int(values['frames_out_of_order']) == LATE, values
    assert int(values['frames_received']) == len(accepted) + LATE + 1, values
    assert int(values['frames_published']) == len(accepted) + 1, values
    assert (values['frames_dropped'], values['bad_frames']) == ('0', '0'), values
    assert any('frame(s) out of order skipped' in text for text in source.messages)
    warnings = [line for line in log.read_text().splitlines() if WARNING in line]
    assert len(warnings) == 1, warnings  # throttled: one line for the whole burst
    assert '/image:' in warnings[0]
    assert f'stamped {last - 1} ns' in warnings[0] and f'stamped {last} ns' in warnings[0]
