"""The ROS 2 environment the package runs in: rclpy, message packages and the Fast DDS profile."""

import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='rclpy is not importable (source scripts/env.sh)')
sensor_msgs = pytest.importorskip('sensor_msgs.msg')

pytestmark = pytest.mark.ros


def test_large_image_round_trip_through_dds() -> None:
    """A 518x378 rgb8 image published BEST_EFFORT arrives intact (shared-memory profile)."""
    from rclpy.qos import qos_profile_sensor_data

    image = np.random.default_rng(3).integers(0, 255, size=(378, 518, 3), dtype=np.uint8)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('infinihand_env_probe', context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    received: list = []
    try:
        node.create_subscription(sensor_msgs.Image, 'probe_image', received.append,
                                 qos_profile_sensor_data)
        publisher = node.create_publisher(sensor_msgs.Image, 'probe_image',
                                          qos_profile_sensor_data)
        msg = sensor_msgs.Image(height=378, width=518, encoding='rgb8', step=518 * 3,
                                data=image.tobytes())
        deadline = time.monotonic() + 10.0
        while not received and time.monotonic() < deadline:
            publisher.publish(msg)
            executor.spin_once(timeout_sec=0.1)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    assert received, 'no image arrived within 10 s'
    got = np.frombuffer(received[0].data, np.uint8).reshape(378, 518, 3)
    np.testing.assert_array_equal(got, image)
