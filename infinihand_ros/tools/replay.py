"""``replay BAG``: play a rosbag2 bag (MCAP or sqlite3, read with rosbags) onto its topics.

Messages go out as recorded (serialized CDR, so every header keeps its original stamp), paced
by the bag's log times: ``--rate 1`` real time, ``--rate N`` N times faster, ``--rate 0`` as fast
as publishing goes. ``--clock`` publishes ``/clock`` (the bag time) before each message, for
subscribers with ``use_sim_time``. ``--topics`` selects topics, ``--remap OLD:=NEW`` renames
them, ``--loop`` plays again and again, ``--wait-for-subscribers S`` waits up to S seconds
for every topic to have a subscriber before starting, ``--delay S`` sleeps S seconds more and
``--playback-duration S`` plays only the first S seconds of bag time (as ``ros2 bag play``).
Topics whose message type has no Python package here are skipped with a note (``make`` builds
our ``infinihand_msgs`` and, without a ROS 2 install, ``tf2_msgs``, so the node's outputs
replay). Exit 0 when done or on SIGINT / SIGTERM, 2 for bad arguments or an unreadable bag.
"""

import argparse
from dataclasses import dataclass
import importlib
from pathlib import Path
import sys
import time
from typing import Any, Final

from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.core.errors import BagError
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.ros.node_process import use_package_dds_profile
import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rosbags.highlevel import AnyReader
from rosbags.highlevel import AnyReaderError
from rosbags.rosbag2 import ReaderError
from rosgraph_msgs.msg import Clock

EXIT_OK: Final = 0
EXIT_USAGE: Final = 2
REMAP_SEPARATOR: Final = ':='
#: Replayed topics: reliable (reaches best-effort and reliable subscribers alike), a few deep.
REPLAY_QOS: Final = QoSProfile(depth=10)
#: Longest wait (s) at the end for the subscribers to acknowledge the last messages.
FLUSH_S: Final = 5.0
POLL_S: Final = 0.05


@dataclass(frozen=True)
class ReplayOptions:
    """Checked command-line options of ``replay``."""

    bag: Path
    rate: float
    clock: bool
    loop: bool
    topics: tuple[str, ...]
    remap: dict[str, str]
    wait_for_subscribers_s: float
    delay_s: float = 0.0
    duration_s: float = 0.0


def parse_args(argv: list[str]) -> ReplayOptions:
    """Parse and check the arguments; exit 2 with one line naming a bad one."""
    parser = argparse.ArgumentParser(prog='replay', description=__doc__.splitlines()[0])
    parser.add_argument('bag', type=Path, help='rosbag2 directory (MCAP or sqlite3)')
    parser.add_argument('--rate', type=float, default=1.0,
                        help='playback speed: 1 real time, N faster, 0 as fast as possible')
    parser.add_argument('--clock', action='store_true', help='publish /clock (bag time)')
    parser.add_argument('--loop', action='store_true', help='play the bag again and again')
    parser.add_argument('--topics', nargs='+', default=[], help='only these topics')
    parser.add_argument('--remap', nargs='+', default=[], metavar='OLD:=NEW',
                        help='publish topic OLD as NEW')
    parser.add_argument('--wait-for-subscribers', type=float, default=0.0, metavar='S',
                        help='wait up to S seconds for every topic to have a subscriber')
    parser.add_argument('--delay', type=float, default=0.0, metavar='S',
                        help='sleep S seconds before playing (after the wait for subscribers)')
    parser.add_argument('--playback-duration', type=float, default=0.0, metavar='S',
                        help='play only the first S seconds of bag time (0: all of it)')
    args = parser.parse_args(argv)
    if not args.rate >= 0.0:
        parser.error(f'--rate must be >= 0, got {args.rate}')
    if not args.wait_for_subscribers >= 0.0:
        parser.error(f'--wait-for-subscribers must be >= 0, got {args.wait_for_subscribers}')
    for name, value in (('--delay', args.delay), ('--playback-duration', args.playback_duration)):
        if not value >= 0.0:
            parser.error(f'{name} must be >= 0, got {value}')
    if not args.bag.is_dir():
        parser.error(f'bag {args.bag} is not a directory; pass a rosbag2 directory')
    remap = {}
    for rule in args.remap:
        old, separator, new = rule.partition(REMAP_SEPARATOR)
        if not separator or not old or not new:
            parser.error(f'--remap {rule!r}: write OLD:=NEW')
        remap[old] = new
    return ReplayOptions(args.bag, args.rate, args.clock, args.loop, tuple(args.topics), remap,
                         args.wait_for_subscribers, args.delay, args.playback_duration)


def message_class(msgtype: str) -> type | None:
    """Return the rclpy class of 'pkg/msg/Name', or None when its package is not importable."""
    package, _, name = msgtype.rpartition('/')
    try:
        return getattr(importlib.import_module(package.replace('/', '.')), name)
    except (ImportError, AttributeError):
        return None


class Replayer:
    """Publishes a bag's messages with their recorded timing."""

    def __init__(self, node: Node, reader: AnyReader, options: ReplayOptions) -> None:
        """Create a publisher per replayable topic of the open ``reader``."""
        self.node, self.reader, self.options = node, reader, options
        self.clock = node.create_publisher(Clock, '/clock', REPLAY_QOS) if options.clock else None
        self.publishers: dict[str, Any] = {}
        missing = sorted(set(options.topics) - {c.topic for c in reader.connections})
        if missing:
            raise BagError(f'bag {options.bag} has no topic(s) {missing}')
        for connection in reader.connections:
            if options.topics and connection.topic not in options.topics:
                continue
            cls = message_class(connection.msgtype)
            if cls is None:
                node.get_logger().info(f'skipping {connection.topic}: no Python package for '
                                       f'{connection.msgtype}')
                continue
            name = options.remap.get(connection.topic, connection.topic)
            self.publishers[connection.topic] = node.create_publisher(cls, name, REPLAY_QOS)

    def wait_for_subscribers(self) -> None:
        """Wait up to the configured time for every publisher to have a subscriber."""
        deadline = time.monotonic() + self.options.wait_for_subscribers_s
        while time.monotonic() < deadline and not all(
                publisher.get_subscription_count() for publisher in self.publishers.values()):
            time.sleep(POLL_S)

    def play_once(self) -> int:
        """Publish every selected message once; return how many were published."""
        connections = [c for c in self.reader.connections if c.topic in self.publishers]
        start_wall, start_bag, count = time.monotonic(), None, 0
        for connection, log_time, raw in self.reader.messages(connections=connections):
            if not rclpy.ok():
                break
            start_bag = log_time if start_bag is None else start_bag
            elapsed_s = (log_time - start_bag) / NS_PER_S
            if self.options.duration_s and elapsed_s >= self.options.duration_s:
                break
            if self.options.rate > 0:
                due = start_wall + elapsed_s / self.options.rate
                time.sleep(max(0.0, due - time.monotonic()))
            if self.clock is not None:
                sec, nanosec = divmod(log_time, NS_PER_S)
                clock = Clock()
                clock.clock.sec, clock.clock.nanosec = sec, nanosec
                self.clock.publish(clock)
            self.publishers[connection.topic].publish(bytes(raw))
            count += 1
        return count

    def flush(self, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` for the subscribers to acknowledge what was published.

        A process that exits right after publishing can take its last messages with it; return
        whether every publisher's were acknowledged in time.
        """
        deadline = time.monotonic() + timeout_s
        return all(publisher.wait_for_all_acked(
            Duration(seconds=max(0.0, deadline - time.monotonic())))
            for publisher in [*self.publishers.values(), *([self.clock] if self.clock else [])])


def replay(options: ReplayOptions) -> int:
    """Replay the bag; return the number of messages published."""
    node = rclpy.create_node('infinihand_replay')
    total = 0
    try:
        with AnyReader([options.bag], default_typestore=build_typestore()) as reader:
            replayer = Replayer(node, reader, options)
            replayer.wait_for_subscribers()
            time.sleep(options.delay_s)
            while rclpy.ok():
                total += replayer.play_once()
                if not options.loop:
                    break
            if rclpy.ok() and not replayer.flush(FLUSH_S):
                node.get_logger().warning(f'some subscribers did not acknowledge the last '
                                          f'messages within {FLUSH_S:.0f} s')
    finally:
        node.destroy_node()
    return total


def main(argv: list[str] | None = None) -> int:
    """Run ``replay``; return the exit code."""
    args = rclpy.utilities.remove_ros_args(sys.argv if argv is None else ['replay', *argv])
    options = parse_args(args[1:])
    use_package_dds_profile()
    rclpy.init(args=sys.argv if argv is None else None)
    try:
        total = replay(options)
    except (BagError, AnyReaderError, ReaderError) as exc:
        print(f'replay: {exc}', file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        return EXIT_OK
    finally:
        rclpy.try_shutdown()
    print(f'replay: published {total} messages from {options.bag}')
    return EXIT_OK


if __name__ == '__main__':
    sys.exit(main())
