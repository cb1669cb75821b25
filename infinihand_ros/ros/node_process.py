"""The process around one of our nodes: init, spin until SIGINT/SIGTERM, clean shutdown.

SIGINT and SIGTERM (rclpy's signal handlers) end the spin; the node's ``close()`` stops its
threads; the process exits 0. A node whose construction raises ``InfiniHandError`` (a bad
parameter, config or checkpoint) logs one error line naming it and the process exits 1.
"""

from collections.abc import Callable
from typing import Final

from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.ros.dds_profile import use_package_dds_profile
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

EXIT_OK: Final = 0
EXIT_BAD_START: Final = 1


def run_node(make_node: Callable[[], Node], name: str, args: list[str] | None = None) -> int:
    """Create the node with ``make_node`` and spin it until shut down; return the exit code.

    The node must have a ``close()`` that stops its threads (both of our nodes do).
    """
    use_package_dds_profile()
    rclpy.init(args=args)
    try:
        node = make_node()
    except InfiniHandError as exc:
        rclpy.logging.get_logger(name).error(f'cannot start: {exc}')
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
