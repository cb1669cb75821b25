"""The installed estimator skips malformed and wrongly encoded images and keeps running."""

from pathlib import Path
import signal
import time

from infinihand_ros.tools.node_processes import fresh_domain_id
from infinihand_ros.tools.node_processes import interrupt
from infinihand_ros.tools.node_processes import ros_env
from infinihand_ros.tools.node_processes import wait_for_text
from live_processes import LIB
from live_processes import running
import numpy as np
import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]
rclpy = pytest.importorskip('rclpy', reason='rclpy is not importable (source scripts/env.sh)')
DiagnosticArray = pytest.importorskip('diagnostic_msgs.msg').DiagnosticArray
qos_profile_sensor_data = pytest.importorskip('rclpy.qos').qos_profile_sensor_data
sensor_msgs = pytest.importorskip('sensor_msgs.msg')
CompressedImage, Image = sensor_msgs.CompressedImage, sensor_msgs.Image

READY = 'ready: engine'
NO_THROTTLE = ['-p', 'bad_frame_log_period_s:=0.001']


def _image(encoding: str, data: bytes, width: int = 8, height: int = 6) -> object:
    msg = Image(height=height, width=width, encoding=encoding, step=width * 3, data=data)
    msg.header.stamp.sec = 1
    return msg


def _publish_and_watch(domain_id: int, messages: list, want_bad: int) -> dict[str, str]:
    """Publish ``messages`` to the node's inputs; return diagnostics once ``want_bad`` counted."""
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node('bad_frame_source', context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    latest: dict[str, str] = {}

    def on_diagnostics(msg: DiagnosticArray) -> None:
        latest.update({v.key: v.value for v in msg.status[0].values})

    try:
        node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
        publishers = {Image: node.create_publisher(Image, 'image', qos_profile_sensor_data),
                      CompressedImage: node.create_publisher(CompressedImage, 'image/compressed',
                                                             qos_profile_sensor_data)}
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and any(
                p.get_subscription_count() == 0 for p in publishers.values()):
            executor.spin_once(timeout_sec=0.1)
        for msg in messages:
            publishers[type(msg)].publish(msg)
            end = time.monotonic() + 1.0  # one at a time: none is dropped as superseded
            while time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)
        while time.monotonic() < deadline and int(latest.get('bad_frames', 0)) < want_bad:
            executor.spin_once(timeout_sec=0.1)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    return latest


@pytest.fixture(autouse=True)
def _installed() -> None:
    if not (LIB / 'estimator').exists():
        pytest.skip('the package is not built (colcon build --symlink-install)')


def test_malformed_images_are_logged_counted_and_skipped(tmp_path: Path) -> None:
    """Truncated, empty and undecodable images: warnings, bad-frame count 4, node alive."""
    domain = fresh_domain_id()
    log = tmp_path / 'estimator.log'
    good = np.zeros((6, 8, 3), dtype=np.uint8).tobytes()
    jpeg_cut = CompressedImage(format='rgb8; jpeg compressed bgr8', data=b'\xff\xd8\xff\xe0' * 8)
    messages = [_image('rgb8', good[:-10]), _image('rgb8', b'', 0, 0), jpeg_cut,
                CompressedImage(format='jpeg', data=b'')]
    with running('estimator', ['--ros-args', *NO_THROTTLE], ros_env(domain), log) as node:
        assert wait_for_text(log, READY, node, 120.0), log.read_text()
        diagnostics = _publish_and_watch(domain, messages, 4)
        assert node.poll() is None, log.read_text()
        assert interrupt(node) == 0
    text = log.read_text()
    assert diagnostics.get('bad_frames') == '4', diagnostics
    for reason in ('do not hold the pixels', 'is empty', 'truncated'):
        assert reason in text


def test_wrong_encodings_are_refused_by_name(tmp_path: Path) -> None:
    """16UC1 / rgba8 Images and a compressedDepth image are refused by name; SIGTERM exits 0."""
    domain = fresh_domain_id()
    log = tmp_path / 'estimator.log'
    messages = [_image('16UC1', bytes(8 * 6 * 2)), _image('rgba8', bytes(8 * 6 * 4)),
                CompressedImage(format='16UC1; compressedDepth png', data=b'\x89PNG')]
    with running('estimator', ['--ros-args', *NO_THROTTLE], ros_env(domain), log) as node:
        assert wait_for_text(log, READY, node, 120.0), log.read_text()
        diagnostics = _publish_and_watch(domain, messages, 3)
        assert node.poll() is None
        assert interrupt(node, signal_number=signal.SIGTERM) == 0
    text = log.read_text()
    assert diagnostics.get('bad_frames') == '3', diagnostics
    for name in ("'16UC1'", "'rgba8'", 'compressedDepth'):
        assert name in text
