"""``record -o OUT TOPIC...``: record live topics into an MCAP rosbag2 bag (rosbags writer).

Messages are taken serialized (CDR) from rclpy and written unchanged, so every header keeps its
stamp; the bag's log time is the receive time on the node clock, as rosbag2 records it. Each
topic is subscribed once its type is discovered, with the QoS its publishers offer (reliable
and transient-local when all of them are, so latched topics are caught too), and logged
(``recording TOPIC (TYPE)``). SIGINT / SIGTERM (or ``--duration``) end the recording and the
bag is closed, with everything received in it. Exit 0 when done, 2 for bad arguments.
"""

import argparse
from dataclasses import dataclass
from pathlib import Path
import sys
import time
from typing import Any, Final

from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.ros.node_process import RCLError
from infinihand_ros.ros.node_process import shut_down_by_signal
from infinihand_ros.ros.node_process import use_package_dds_profile
from infinihand_ros.tools.replay import message_class
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy
from rclpy.qos import QoSProfile
from rclpy.qos import ReliabilityPolicy
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer

EXIT_OK: Final = 0
EXIT_USAGE: Final = 2
ROSBAG_VERSION: Final = 9
#: How often topics not yet discovered are looked for, s.
DISCOVERY_PERIOD_S: Final = 0.2
RECORD_DEPTH: Final = 100
#: Logged once per topic when its subscription is made.
RECORDING: Final = 'recording'


@dataclass(frozen=True)
class RecordOptions:
    """Checked command-line options of ``record``."""

    output: Path
    topics: tuple[str, ...]
    duration_s: float


def parse_args(argv: list[str]) -> RecordOptions:
    """Parse and check the arguments; exit 2 with one line naming a bad one."""
    parser = argparse.ArgumentParser(prog='record', description=__doc__.splitlines()[0])
    parser.add_argument('-o', '--output', type=Path, required=True,
                        help='bag directory to create (must not exist)')
    parser.add_argument('topics', nargs='+', help='absolute topic names to record')
    parser.add_argument('--duration', type=float, default=0.0, metavar='S',
                        help='stop after S seconds (0: until SIGINT / SIGTERM)')
    args = parser.parse_args(argv)
    if args.output.exists():
        parser.error(f'-o {args.output} exists; choose a new directory')
    if not args.output.parent.is_dir():
        parser.error(f'-o {args.output}: its parent directory does not exist')
    relative = [topic for topic in args.topics if not topic.startswith('/')]
    if relative:
        parser.error(f'topics must be absolute (start with /), got {relative}')
    if not args.duration >= 0.0:
        parser.error(f'--duration must be >= 0, got {args.duration}')
    return RecordOptions(args.output, tuple(dict.fromkeys(args.topics)), args.duration)


def matching_qos(node: Node, topic: str) -> QoSProfile:
    """Return a subscription QoS that connects to every publisher of ``topic``."""
    infos = node.get_publishers_info_by_topic(topic)
    reliable = bool(infos) and all(
        info.qos_profile.reliability == ReliabilityPolicy.RELIABLE for info in infos)
    latched = bool(infos) and all(
        info.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for info in infos)
    return QoSProfile(depth=RECORD_DEPTH,
                      reliability=(ReliabilityPolicy.RELIABLE if reliable
                                   else ReliabilityPolicy.BEST_EFFORT),
                      durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched
                                  else DurabilityPolicy.VOLATILE))


class Recorder:
    """Subscribes to the topics as they appear and writes what arrives."""

    def __init__(self, node: Node, writer: Writer, topics: tuple[str, ...]) -> None:
        """Start looking for ``topics`` on the graph."""
        self.node, self.writer = node, writer
        self.typestore = build_typestore()
        self.pending = list(topics)
        self.counts: dict[str, int] = dict.fromkeys(topics, 0)
        self._subscriptions: list[Any] = []
        node.create_timer(DISCOVERY_PERIOD_S, self.discover)
        self.discover()

    def discover(self) -> None:
        """Subscribe to every pending topic whose type is now known."""
        types = dict(self.node.get_topic_names_and_types())
        for topic in [topic for topic in self.pending if topic in types]:
            msgtype = types[topic][0]
            cls = message_class(msgtype)
            if cls is None:
                self.node.get_logger().warning(f'cannot record {topic}: no Python package for '
                                               f'{msgtype}', once=True)
                continue
            connection = self.writer.add_connection(topic, msgtype, typestore=self.typestore)
            self._subscriptions.append(self.node.create_subscription(
                cls, topic, lambda data, t=topic, c=connection: self._write(t, c, data),
                matching_qos(self.node, topic), raw=True))
            self.pending.remove(topic)
            self.node.get_logger().info(f'{RECORDING} {topic} ({msgtype})')

    def _write(self, topic: str, connection: Any, data: bytes) -> None:
        """Write one serialized message at the receive time."""
        self.writer.write(connection, self.node.get_clock().now().nanoseconds, data)
        self.counts[topic] += 1


def record(options: RecordOptions) -> dict[str, int]:
    """Record until shutdown (or the duration); return the message count per topic."""
    node = rclpy.create_node('infinihand_record')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    writer = Writer(options.output, version=ROSBAG_VERSION, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    counts = dict.fromkeys(options.topics, 0)
    try:
        counts = Recorder(node, writer, options.topics).counts
        end = time.monotonic() + options.duration_s if options.duration_s else None
        while rclpy.ok() and (end is None or time.monotonic() < end):
            executor.spin_once(timeout_sec=DISCOVERY_PERIOD_S)
    except (KeyboardInterrupt, ExternalShutdownException, RCLError) as exc:
        if not shut_down_by_signal(exc):
            raise
    finally:
        writer.close()
        executor.shutdown()
        node.destroy_node()
    return counts


def main(argv: list[str] | None = None) -> int:
    """Run ``record``; return the exit code."""
    args = rclpy.utilities.remove_ros_args(sys.argv if argv is None else ['record', *argv])
    options = parse_args(args[1:])
    use_package_dds_profile()
    rclpy.init(args=sys.argv if argv is None else None)
    try:
        counts = record(options)
    except (KeyboardInterrupt, RCLError) as exc:  # SIGINT while the node was being created
        if not shut_down_by_signal(exc):
            raise
        print('record: interrupted before recording started', file=sys.stderr)
        return EXIT_OK
    finally:
        rclpy.try_shutdown()
    summary = ', '.join(f'{topic} {count}' for topic, count in counts.items())
    print(f'record: wrote {options.output} ({summary})')
    return EXIT_OK


if __name__ == '__main__':
    sys.exit(main())
