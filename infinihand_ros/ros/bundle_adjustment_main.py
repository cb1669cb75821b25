"""``ros2 run infinihand_ros bundle_adjustment``: the process around the BA node.

``main`` owns init, the executor and shutdown: SIGINT and SIGTERM end the spin, the BA worker is
stopped (a running call gets ``close_timeout_s``) and the process exits 0. A bad parameter stops
it at start-up with one error line naming it, exit code 1. Start it next to an estimator run
with ``engine.bundle_adjustment:=node``; either may start first or restart.
"""

import sys

from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.ros.bundle_adjustment_config import BA_NODE_NAME
from infinihand_ros.ros.bundle_adjustment_node import BundleAdjustmentNode
from infinihand_ros.ros.dds_profile import use_package_dds_profile
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.executors import SingleThreadedExecutor

EXIT_OK = 0
EXIT_BAD_START = 1


def main(args: list[str] | None = None) -> int:
    """Run the BA node until shut down; return the exit code."""
    use_package_dds_profile()
    rclpy.init(args=args)
    try:
        node = BundleAdjustmentNode()
    except InfiniHandError as exc:
        rclpy.logging.get_logger(BA_NODE_NAME).error(f'cannot start: {exc}')
        rclpy.try_shutdown()
        return EXIT_BAD_START
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.close()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return EXIT_OK


if __name__ == '__main__':
    sys.exit(main())
