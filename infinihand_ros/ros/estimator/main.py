"""``ros2 run infinihand_ros estimator``: the process around the estimator node.

``main`` runs it with ``node_process.run_node``: SIGINT and SIGTERM (rclpy's signal handlers)
end the spin, the inference thread and the engine are stopped, and the process exits 0. A bad
parameter or checkpoint stops it at start-up with one error line naming it, exit code 1.
"""

import sys

from infinihand_ros.ros.estimator.config import NODE_NAME
from infinihand_ros.ros.estimator.node import EstimatorNode
from infinihand_ros.ros.node_process import run_node


def main(args: list[str] | None = None) -> int:
    """Run the estimator node until shut down; return the exit code."""
    return run_node(EstimatorNode, NODE_NAME, args)


if __name__ == '__main__':
    sys.exit(main())
