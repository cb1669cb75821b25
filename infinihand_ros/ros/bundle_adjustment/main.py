"""``ros2 run infinihand_ros bundle_adjustment``: the process around the BA node.

``main`` runs it with ``node_process.run_node``: SIGINT and SIGTERM end the spin, the BA worker is
stopped (a running call gets ``close_timeout_s``) and the process exits 0. A bad parameter stops
it at start-up with one error line naming it, exit code 1. Start it next to an estimator run
with ``engine.bundle_adjustment:=node``; either may start first or restart.
"""

import sys

from infinihand_ros.ros.bundle_adjustment.config import BA_NODE_NAME
from infinihand_ros.ros.bundle_adjustment.node import BundleAdjustmentNode
from infinihand_ros.ros.node_process import run_node


def main(args: list[str] | None = None) -> int:
    """Run the BA node until shut down; return the exit code."""
    return run_node(BundleAdjustmentNode, BA_NODE_NAME, args)


if __name__ == '__main__':
    sys.exit(main())
