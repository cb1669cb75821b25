"""``ros2 run infinihand_ros estimator``: the process around the estimator node.

``main`` owns init, the executor and shutdown: SIGINT and SIGTERM (rclpy's signal handlers)
end the spin, the inference thread and the engine are stopped, and the process exits 0. A bad
parameter or checkpoint stops it at start-up with one error line naming it, exit code 1.
"""

import sys

from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.ros.dds_profile import use_package_dds_profile
from infinihand_ros.ros.estimator_node import EstimatorNode
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.executors import SingleThreadedExecutor

EXIT_OK = 0
EXIT_BAD_START = 1


def main(args: list[str] | None = None) -> int:
    """Run the estimator node until shut down; return the exit code."""
    use_package_dds_profile()
    rclpy.init(args=args)
    try:
        node = EstimatorNode()
    except InfiniHandError as exc:
        rclpy.logging.get_logger('infinihand_estimator').error(f'cannot start: {exc}')
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
