"""The installed estimator skips late images and restarts its stream when stamps jump back.

Frames are accepted (until the engine's anchor frames are out), then a burst of late and
repeated stamps arrives (at most ``camera.restart_after_s`` back), then a newer frame: the burst
is counted in ``frames_out_of_order`` (not as dropped or bad), the throttled warning names the
topic and both stamps once, and the newer frame is still estimated. A stream sent twice with the
same stamps (a replay loop) restarts once: the second pass is published as a new stream, with a
camera path of its own.
"""

from collections.abc import Iterator
import contextlib
import pathlib
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
Path = pytest.importorskip('nav_msgs.msg').Path
Image = pytest.importorskip('sensor_msgs.msg').Image
qos = pytest.importorskip('rclpy.qos')

READY = 'ready: engine'
NS_PER_S = 1_000_000_000
FIRST_NS = 100 * NS_PER_S
#: In-order frames sent at most before the engine's anchor frames must have come out.
MAX_ACCEPTED = 10
#: Frames stamped no later than the last accepted one: late, repeated, up to 0.9 s older.
LATE = 20
LATE_STEP_NS = 50_000_000
WARNING = 'skipping an image stamped'
RESTART_WARNING = 'a new stream starts'
CAMERA_PATH = '/infinihand_estimator/camera_path'
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
        self.path_stamps: list[int] = []  # of the last ~/camera_path
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        self.node.create_subscription(Path, CAMERA_PATH, self._on_path, qos.QoSProfile(
            depth=1, reliability=qos.ReliabilityPolicy.RELIABLE,
            durability=qos.DurabilityPolicy.TRANSIENT_LOCAL))
        self.images = self.node.create_publisher(
            Image, 'image', qos.QoSProfile(depth=100, reliability=qos.ReliabilityPolicy.RELIABLE))

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        self.values = {v.key: v.value for v in msg.status[0].values}
        self.messages.append(msg.status[0].message)

    def _on_path(self, msg: Path) -> None:
        self.path_stamps = [pose.header.stamp.sec * NS_PER_S + pose.header.stamp.nanosec
                            for pose in msg.poses]

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

    def send_stream(self, rgb: np.ndarray, log: pathlib.Path, extra: int = 0) -> list[int]:
        """Send frames 1 s apart from FIRST_NS, each once the engine took the one before.

        Until one of them is published (the engine's anchor frames are out), then ``extra``
        more; return their stamps once all of them are published.
        """
        processed, published = self.processed(), self.count('frames_published')
        stamps: list[int] = []
        while self.count('frames_published') == published and len(stamps) < MAX_ACCEPTED:
            self._send_next(rgb, stamps, processed, log)
        for _ in range(extra):
            self._send_next(rgb, stamps, processed, log)
        assert self.spin_until(lambda: self.count(
            'frames_published') == published + len(stamps), 120.0), log.read_text()
        return stamps

    def _send_next(self, rgb: np.ndarray, stamps: list[int], processed: int,
                   log: pathlib.Path) -> None:
        stamps.append(FIRST_NS + len(stamps) * NS_PER_S)
        self.images.publish(_image(rgb, stamps[-1]))
        assert self.spin_until(lambda: self.processed() == processed + len(stamps), 120.0), (
            log.read_text())

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


@contextlib.contextmanager
def _live_node(tmp_path: pathlib.Path) -> Iterator[tuple[np.ndarray, '_Source', pathlib.Path]]:
    """Run the estimator with lossless input and a source it subscribes to.

    Yields (a sample-bag image, the source, the node's log). On leaving, one more diagnostics
    period is taken, and the node must still run and exit 0 on SIGINT.
    """
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
            yield rgb, source, log
            source.spin_until(lambda: False, 1.5)  # one more diagnostics period
        finally:
            source.close()
        assert node.poll() is None, log.read_text()
        assert interrupt(node) == 0


def test_late_and_repeated_stamps_are_counted_and_skipped(tmp_path: pathlib.Path) -> None:
    """20 stale stamps: frames_out_of_order 20, one warning, no bad frame or restart."""
    with _live_node(tmp_path) as (rgb, source, log):
        accepted = source.send_stream(rgb, log)
        last = accepted[-1]
        late = [last - 1, last, *(last - k * LATE_STEP_NS for k in range(1, LATE - 1))]
        for stamp in late:  # back to back: none may replace a frame waiting in the node
            source.images.publish(_image(rgb, stamp))
        source.images.publish(_image(rgb, last + NS_PER_S))
        assert source.spin_until(lambda: source.count(
            'frames_published') == len(accepted) + 1, 120.0), log.read_text()
    values = source.values
    assert int(values['frames_out_of_order']) == LATE, values
    assert int(values['frames_received']) == len(accepted) + LATE + 1, values
    assert int(values['frames_published']) == len(accepted) + 1, values
    assert (values['frames_dropped'], values['bad_frames'], values['stream_restarts']) == (
        '0', '0', '0'), values
    assert any('frame(s) out of order skipped' in text for text in source.messages)
    warnings = [line for line in log.read_text().splitlines() if WARNING in line]
    assert len(warnings) == 1, warnings  # throttled: one line for the whole burst
    assert '/image:' in warnings[0]
    assert f'stamped {last - 1} ns' in warnings[0] and f'stamped {last} ns' in warnings[0]


def test_the_same_stamps_again_restart_the_stream(tmp_path: pathlib.Path) -> None:
    """A replay loop: one restart and its warning, the second pass published, a new path."""
    with _live_node(tmp_path) as (rgb, source, log):
        first = source.send_stream(rgb, log, extra=2)
        assert source.spin_until(lambda: source.path_stamps == first, 30.0)
        second = source.send_stream(rgb, log)  # the same stamps from the start, fewer
        assert source.spin_until(lambda: source.path_stamps == second, 30.0), (
            source.path_stamps, first, second)
    values = source.values
    assert len(second) < len(first) and second == first[:len(second)]
    assert int(values['stream_restarts']) == 1, values
    assert int(values['frames_published']) == len(first) + len(second), values
    assert (values['frames_out_of_order'], values['frames_dropped'], values['bad_frames']) == (
        '0', '0', '0'), values
    assert any('stream restarted 1 time(s)' in text for text in source.messages)
    warnings = [line for line in log.read_text().splitlines() if RESTART_WARNING in line]
    assert len(warnings) == 1, warnings
    assert '/image:' in warnings[0] and 'the world frame restarts' in warnings[0]
    assert f'stamped {FIRST_NS} ns' in warnings[0] and f'stamped {first[-1]} ns' in warnings[0]
