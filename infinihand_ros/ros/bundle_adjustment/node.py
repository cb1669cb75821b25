"""The ``infinihand_bundle_adjustment`` node: keyframes in, refined poses and corrections out.

A thin adapter over the BA core: keyframe messages (``keyframe_msgs``) are put back together by
stamp (``KeyframeAssembler``) and handed to a ``BundleAdjustmentSession`` (binary keyframe pool,
BA worker in its own process). Each finished BA call is published from the worker's thread as
corrections on ``bundle_adjustment/corrections`` (the estimator applies them) and as the
latched ``~/refined_keyframe_path`` (nav_msgs/Path of every refined keyframe pose still held).
A status goes to ``/diagnostics`` and, as the estimator's heartbeat, to
``bundle_adjustment/status``. A bad keyframe is logged (throttled), counted and skipped.

``main`` runs it with ``node_process.run_node``: SIGINT and SIGTERM end the spin, the BA worker is
stopped (a running call gets ``close_timeout_s``) and the process exits 0. A bad parameter stops
it at start-up with one error line naming it, exit code 1. Start it next to an estimator run
with ``engine.bundle_adjustment:=node``; either may start first or restart.
"""

import sys
from typing import Any, Final

from diagnostic_msgs.msg import DiagnosticArray
from infinihand_ros.ba.corrections import Corrections
from infinihand_ros.ba.session import BundleAdjustmentSession
from infinihand_ros.ba.worker_statistics import WorkerState
from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.output_fields import PoseFields
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.ros import msg_builders
from infinihand_ros.ros.bundle_adjustment.config import ba_node_config_from_parameters
from infinihand_ros.ros.bundle_adjustment.config import BA_NODE_NAME
from infinihand_ros.ros.bundle_adjustment.config import BundleAdjustmentNodeConfig
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import corrections_msg
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import CORRECTIONS_TOPIC
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import keyframe_from_msgs
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import KEYFRAME_PARTS
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import KEYFRAME_PREFIX
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import KeyframeAssembler
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import LINK_QOS
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import STATE_KEY
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import STATUS_TOPIC
from infinihand_ros.ros.estimator.diagnostics import DiagnosticReport
from infinihand_ros.ros.estimator.node_statistics import OK
from infinihand_ros.ros.estimator.node_statistics import WARN
from infinihand_ros.ros.estimator.publishers import LATCHED_QOS
from infinihand_ros.ros.node_process import parse_command_line
from infinihand_ros.ros.node_process import run_node
from infinihand_ros.ros.parameters import declare_parameters
from nav_msgs.msg import Path
from rclpy.node import Node

DIAGNOSTICS_TOPIC: Final = '/diagnostics'
LOG_PERIOD_S: Final = 5.0


class BundleAdjustmentNode(Node):
    """Parameters, keyframe subscriptions, the BA session and the result publishers."""

    def __init__(self, **node_kwargs: Any) -> None:
        """Declare and check the parameters, load the BA settings, start the BA worker.

        Raises:
            ConfigError: naming the parameter (or the BA file's key) for a bad value.

        """
        super().__init__(BA_NODE_NAME, **node_kwargs)
        self.config = declare_parameters(self, BundleAdjustmentNodeConfig,
                                         ba_node_config_from_parameters)
        try:
            ba = self.config.ba_config()
        except ConfigError as exc:
            raise ConfigError(f'parameter {exc}') from exc
        self._assembler = KeyframeAssembler(tuple(KEYFRAME_PARTS),
                                            self.config.keyframes.max_pending)
        self._bad = 0
        self._corrections = self.create_publisher(Path, CORRECTIONS_TOPIC, LINK_QOS)
        self._path = self.create_publisher(Path, '~/refined_keyframe_path', LATCHED_QOS)
        self._status = self.create_publisher(DiagnosticArray, STATUS_TOPIC, LINK_QOS)
        self._diagnostics = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, 10)
        self.session = BundleAdjustmentSession(
            ba, int(self.config.keyframes.max_gap_s * NS_PER_S), self.config.refined_path_length,
            self._publish_result)
        for part, msg_type in KEYFRAME_PARTS.items():
            self.create_subscription(msg_type, KEYFRAME_PREFIX + part,
                                     lambda msg, part=part: self._on_part(part, msg), LINK_QOS)
        self.create_timer(self.config.status_period_s, self._publish_status)
        self.get_logger().info(f'ready: pool N={ba.pool.trigger} K={ba.pool.stride}, BA '
                               f'niceness {ba.worker.niceness}')

    def close(self) -> None:
        """Stop the BA worker (call before ``destroy_node``)."""
        self.session.close(self.config.close_timeout_s)

    def _on_part(self, part: str, msg: Any) -> None:
        """Collect a keyframe part; a completed keyframe goes to the session."""
        parts = self._assembler.add(part, ns_from_stamp(msg.header.stamp), msg)
        if parts is None:
            return
        try:
            keyframe = keyframe_from_msgs(parts, self.session.keyframes)
        except InputError as exc:
            self._bad += 1
            self.get_logger().warning(f'skipping a keyframe: {exc}',
                                      throttle_duration_sec=LOG_PERIOD_S)
            return
        if self.session.add(keyframe):
            self.get_logger().debug(f'BA selection up to keyframe {keyframe.timestamp_ns}')

    def _publish_result(self, corrections: Corrections) -> None:
        """Publish one BA call's corrections and the refined path (BA worker thread)."""
        stamp = int(corrections.times_ns.max())
        world = self.config.world_frame_id
        self._corrections.publish(corrections_msg(stamp, world, corrections))
        poses = [(time_ns, PoseFields.from_rotation(pose[:3, :3], pose[:3, 3]))
                 for time_ns, pose in self.session.refined_poses()]
        self._path.publish(msg_builders.path_msg(stamp, world, poses))
        self.get_logger().info(f'refined {len(corrections.times_ns)} keyframes up to {stamp}')

    def _publish_status(self) -> None:
        """Publish the status on /diagnostics and as the heartbeat."""
        msg = msg_builders.diagnostic_array_msg(
            self.get_clock().now().nanoseconds, f'{self.get_name()}: bundle adjustment',
            self.get_fully_qualified_name(), self.status_report())
        self._status.publish(msg)
        self._diagnostics.publish(msg)

    def status_report(self) -> DiagnosticReport:
        """Return the worker's state and counters and the keyframe intake's."""
        worker = self.session.worker.statistics
        values = ((STATE_KEY, str(worker.state)), ('keyframes', self.session.keyframes),
                  ('keyframes_incomplete', self._assembler.dropped),
                  ('bad_keyframes', self._bad), ('sequences', self.session.sequences),
                  ('calls_submitted', worker.submitted), ('calls_done', worker.done),
                  ('calls_dropped', worker.dropped), ('calls_failed', worker.failed),
                  ('calls_rejected', worker.rejected),
                  ('process_starts', worker.process_starts),
                  ('last_error', worker.last_error or ''))
        failing = worker.state == WorkerState.FAILED or worker.failed > 0
        message = f'BA {worker.state}' + (f'; last error: {worker.last_error}'
                                          if worker.last_error else '')
        return DiagnosticReport(WARN if failing else OK, message,
                                tuple((key, str(value)) for key, value in values))


DESCRIPTION: Final = (
    'The InfiniHand bundle-adjustment node: refines the keyframes an estimator running with\n'
    'engine.bundle_adjustment:=node sends (bundle_adjustment/keyframes/*) and answers with\n'
    'corrections (bundle_adjustment/corrections).')


def main(args: list[str] | None = None) -> int:
    """Run the node until shut down (``--help``: print the node and its parameters)."""
    parse_command_line('bundle_adjustment', DESCRIPTION, BundleAdjustmentNodeConfig, args)
    return run_node(BundleAdjustmentNode, BA_NODE_NAME, args)


if __name__ == '__main__':
    sys.exit(main())
