"""The estimator's transport for ``engine.bundle_adjustment: node``: messages <-> ``RemoteBA``.

The engine offers keyframes to its ``RemoteBA`` backend; ``send_keyframes`` publishes them
(``keyframe_msgs``) only while the BA node subscribes to every part, so an absent node costs
nothing. Corrections arrive in a callback and go to the backend, which the engine folds into
its pose track before the next frame (or when the node asks between frames). The BA node's
status messages are the heartbeat of a ``BANodeLink``; its state changes are logged once each
and reported in diagnostics. Wall time (monotonic) measures the heartbeat, so a replay's
``/clock`` pausing cannot hide an outage.

The link is 'waiting' before the first status, 'connected' while they keep coming, and 'lost'
once none came for ``timeout_s`` (the node died or hangs). Either way the estimator goes on
with unrefined poses; a node that comes back is 'connected' again and its corrections apply.
Keyframe stamps sent are remembered (bounded), so corrections of keyframes this estimator never
sent (another estimator's stream, one before a restart) are refused; when the estimator's stream
restarts they are forgotten (``restart``), so late corrections of the stream before are refused
too. The BA node starts a new sequence by itself when a keyframe's stamp goes back.
``BANodeLink`` is thread-safe: heartbeats and corrections arrive in callbacks while the
inference thread reads.
"""

from collections import deque
import threading
import time
from typing import Final

from diagnostic_msgs.msg import DiagnosticArray
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.core.errors import InputError
from infinihand_ros.engine.ba_remote import RemoteBA
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import corrections_from_msg
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import CORRECTIONS_TOPIC
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import keyframe_msgs
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import KEYFRAME_PARTS
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import KEYFRAME_PREFIX
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import LINK_QOS
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import STATE_KEY
from infinihand_ros.ros.bundle_adjustment.keyframe_msgs import STATUS_TOPIC
from infinihand_ros.ros.estimator.config import BANodeLinkConfig
from infinihand_ros.ros.estimator.diagnostics import CONNECTED
from infinihand_ros.ros.estimator.diagnostics import LOST
from infinihand_ros.ros.estimator.diagnostics import UNAVAILABLE
from infinihand_ros.ros.estimator.diagnostics import WAITING
from nav_msgs.msg import Path
import numpy as np
from rclpy.node import Node


class BANodeLink:
    """Heartbeats, sent keyframe stamps and applied results of the BA node link."""

    def __init__(self, timeout_s: float, stamps_kept: int) -> None:
        """Start 'waiting'; remember the last ``stamps_kept`` keyframe stamps sent."""
        self.timeout_s = timeout_s
        self._lock = threading.Lock()
        self._last_heard_s: float | None = None
        self._node_state = 'unknown'
        self._reported = WAITING
        self._sent: deque[int] = deque(maxlen=stamps_kept)
        self._sent_set: set[int] = set()
        self.counts = {'keyframes_sent': 0, 'results_refused': 0, 'outages': 0}

    def heard(self, now_s: float, node_state: str) -> None:
        """Record a status from the BA node at ``now_s`` (its worker state)."""
        with self._lock:
            self._last_heard_s = now_s
            self._node_state = node_state

    def state(self, now_s: float) -> str:
        """Return 'waiting', 'connected' or 'lost' at ``now_s``."""
        with self._lock:
            return self._state(now_s)

    def changed(self, now_s: float) -> str | None:
        """Return the state when it differs from the last call's (None otherwise)."""
        with self._lock:
            state = self._state(now_s)
            if state == self._reported:
                return None
            if state == LOST:
                self.counts['outages'] += 1
            self._reported = state
            return state

    def sent(self, stamp_ns: int) -> None:
        """Remember a keyframe stamp sent to the BA node."""
        with self._lock:
            if len(self._sent) == self._sent.maxlen:
                self._sent_set.discard(self._sent[0])
            self._sent.append(stamp_ns)
            self._sent_set.add(stamp_ns)
            self.counts['keyframes_sent'] += 1

    def forget_sent(self) -> None:
        """Forget the keyframe stamps sent (their stream ended): their results are refused."""
        with self._lock:
            self._sent.clear()
            self._sent_set.clear()

    def accepts(self, times_ns: np.ndarray) -> bool:
        """Return whether every stamp of a result is a keyframe this link sent (else count it)."""
        with self._lock:
            ok = all(int(stamp) in self._sent_set for stamp in times_ns)
            self.counts['results_refused'] += int(not ok)
            return ok

    def statistics(self, now_s: float) -> dict[str, object]:
        """Return the link for diagnostics: ``state``, the node's state and the counters."""
        with self._lock:
            return {'state': self._state(now_s), 'node_state': self._node_state,
                    **self.counts}

    def _state(self, now_s: float) -> str:
        """Return the state; the caller holds the lock."""
        if self._last_heard_s is None:
            return WAITING
        return CONNECTED if now_s - self._last_heard_s <= self.timeout_s else LOST


#: Keyframe stamps remembered to check corrections against (more than a BA pool holds).
STAMPS_KEPT: Final = 4096
LOG_PERIOD_S: Final = 5.0


class BANodeClient:
    """Keyframe publishers, the corrections subscription and the link to the BA node."""

    def __init__(self, node: Node, config: BANodeLinkConfig, world_frame_id: str,
                 remote: RemoteBA) -> None:
        """Create the keyframe publishers and subscribe to the BA node's outputs."""
        self._node = node
        self._world = world_frame_id
        self.remote = remote
        self.link = BANodeLink(config.timeout_s, STAMPS_KEPT)
        self._folded_in_logged = 0
        self._publishers = {part: node.create_publisher(msg_type, KEYFRAME_PREFIX + part,
                                                        LINK_QOS)
                            for part, msg_type in KEYFRAME_PARTS.items()}
        node.create_subscription(Path, CORRECTIONS_TOPIC, self._on_corrections, LINK_QOS)
        node.create_subscription(DiagnosticArray, STATUS_TOPIC, self._on_status, LINK_QOS)

    def publish(self, keyframe: KeyframeInput, camera_frame_id: str) -> bool:
        """Send a keyframe when the BA node listens to every part; return whether it went."""
        if not all(publisher.get_subscription_count() for publisher in
                   self._publishers.values()):
            return False
        for part, msg in keyframe_msgs(keyframe, self._world, camera_frame_id).items():
            self._publishers[part].publish(msg)
        self.link.sent(keyframe.timestamp_ns)
        return True

    def report_folded_in(self) -> None:
        """Log the BA results the engine folded into its pose track since the last call."""
        folded_in = self.remote.statistics()['folded_in']
        if folded_in > self._folded_in_logged:
            self._node.get_logger().info(f'applied bundle-adjustment corrections '
                                         f'({folded_in - self._folded_in_logged} BA results)')
            self._folded_in_logged = folded_in

    def send_keyframes(self, camera_frame_id: str) -> None:
        """Publish the keyframes the engine offered since the last call."""
        for keyframe in self.remote.take_keyframes():
            self.publish(keyframe, camera_frame_id)

    def restart(self) -> None:
        """Start a new stream: corrections of keyframes sent before are refused from now on."""
        self.link.forget_sent()

    def check(self) -> None:
        """Log a change of the link's state (once per change)."""
        state = self.link.changed(time.monotonic())
        if state in UNAVAILABLE:
            self._node.get_logger().warning(f'bundle-adjustment node {UNAVAILABLE[state]}: '
                                            'poses go on unrefined')
        elif state is not None:
            self._node.get_logger().info(f'bundle-adjustment node {state}')

    def statistics(self) -> dict[str, object]:
        """Return the link's figures and the results folded in, for diagnostics."""
        return {**self.link.statistics(time.monotonic()),
                'folded_in': self.remote.statistics()['folded_in']}

    def _on_corrections(self, msg: Path) -> None:
        """Queue a BA result for the keyframes this estimator sent; refuse others."""
        try:
            corrections = corrections_from_msg(msg)
        except InputError as exc:
            self._node.get_logger().warning(f'ignoring BA corrections: {exc}',
                                            throttle_duration_sec=LOG_PERIOD_S)
            return
        if not self.link.accepts(corrections.times_ns):
            self._node.get_logger().warning(
                'ignoring BA corrections of keyframes this estimator did not send (an earlier '
                'stream)', throttle_duration_sec=LOG_PERIOD_S)
            return
        self.remote.receive(corrections)

    def _on_status(self, msg: DiagnosticArray) -> None:
        """Take a BA node status as its heartbeat."""
        values = {kv.key: kv.value for status in msg.status for kv in status.values}
        self.link.heard(time.monotonic(), values.get(STATE_KEY, 'unknown'))
