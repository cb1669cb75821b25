"""The ``infinihand_estimator`` node: camera stream in, camera pose and world-space hands out.

A thin adapter: message -> ``image_decoding`` / ``camera_info_pairing`` -> ``StreamingEngine``
(estimation and the output stage every consumer shares) -> ``OutputPublishers``. The image
callbacks only put the message into a one-frame mailbox (``LatestFrameSlot``); a dedicated
inference thread takes the newest one, so frames arriving while the model is busy are dropped and
counted and the latency never grows. With a fixed camera and MediaPipe hands (the teleop case) the
callback also decodes the image and starts its hand detection at once
(``StreamingEngine.detect_ahead``), so it runs while the last frame is still being finished. A bad
frame (encoding, size, truncated data, bad CameraInfo) is logged, throttled, counted and skipped;
so is an image whose stamp is not after the last accepted image's (late or repeated: the engine
needs increasing stamps), checked before it can replace a waiting frame and again before it is
decoded. An image stamped more than the engine's ``restart_after_s`` (1 s; ``engine.set``)
before the last accepted one (a
replay looping, a camera restarting, normal stamps after a far-future one) starts a new stream
instead: the engine resets (a new world frame, pose track and BA), the camera path and the stream's
CameraInfos start afresh, and the image is the new stream's first; one warning and
``stream_restarts`` say so. The engine's stream policy (``engine/stream_policy.py``) decides;
the node asks it first
(``StreamingEngine.stamp_step``) to skip or restart before it decodes and pairs the image.
Inputs (relative, remappable): ``image``, ``image/compressed``, ``camera_info``, with
sensor-data QoS overridable by parameters. Bundle adjustment is off by
default (``engine.bundle_adjustment: none``); with ``in_process`` it runs in the engine's
background worker process, no frame waits for it, and its corrections move later poses. With
``engine.bundle_adjustment: node`` the engine's ``RemoteBA`` backend offers keyframes and takes
corrections, and ``BANodeClient`` carries them to and from the bundle-adjustment node (corrections
are folded in before each frame and while no frame comes); without that node the poses go on
unrefined and diagnostics say so.

``main`` runs it with ``node_process.run_node``: SIGINT and SIGTERM (rclpy's signal handlers)
end the spin, the inference thread and the engine are stopped, and the process exits 0. A bad
parameter or checkpoint stops it at start-up with one error line naming it, exit code 1.
"""

from collections import OrderedDict
import contextlib
import copy
import sys
import threading
import time
from typing import Any, Final

from diagnostic_msgs.msg import DiagnosticArray
from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.core import topics
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.errors import ModelOutputError
from infinihand_ros.core.latest_frame import LatestFrameSlot
from infinihand_ros.core.output_fields import PoseFields
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.engine.ba_remote import RemoteBA
from infinihand_ros.engine.output.camera_path import CameraPath
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.engine.timestamps import StampStep
from infinihand_ros.ros import msg_builders
from infinihand_ros.ros.estimator.ba_node_client import BANodeClient
from infinihand_ros.ros.estimator.camera_info_pairing import CameraInfoPairing
from infinihand_ros.ros.estimator.camera_info_pairing import IntrinsicsChoice
from infinihand_ros.ros.estimator.config import estimator_config_from_parameters
from infinihand_ros.ros.estimator.config import EstimatorConfig
from infinihand_ros.ros.estimator.config import NODE_NAME
from infinihand_ros.ros.estimator.diagnostics import diagnostic_report
from infinihand_ros.ros.estimator.engine_setup import engine_config_for
from infinihand_ros.ros.estimator.image_decoding import decode_image
from infinihand_ros.ros.estimator.node_statistics import EstimatorStatistics
from infinihand_ros.ros.estimator.node_statistics import StatisticsSnapshot
from infinihand_ros.ros.estimator.publishers import OutputPublishers
from infinihand_ros.ros.node_process import parse_command_line
from infinihand_ros.ros.node_process import run_node
from infinihand_ros.ros.parameters import declare_parameters
import numpy as np
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import CameraInfo
from sensor_msgs.msg import CompressedImage
from sensor_msgs.msg import Image

#: How often the inference thread checks for shutdown while no frame comes, s.
TAKE_TIMEOUT_S: Final = 0.2
DIAGNOSTICS_TOPIC: Final = '/diagnostics'
#: Arrival times remembered (the engine holds back at most its anchor frames).
ARRIVALS_KEPT: Final = 256


class EstimatorNode(Node):
    """Parameters, subscriptions, publishers and the inference thread of the estimator."""

    def __init__(self, **node_kwargs: Any) -> None:
        """Declare and check the parameters, build the engine, start the inference thread.

        Raises:
            ConfigError: naming the parameter for a bad value.
            CheckpointError: for a checkpoint that cannot be loaded.

        """
        super().__init__(NODE_NAME, **node_kwargs)
        self.config = declare_parameters(self, EstimatorConfig, estimator_config_from_parameters)
        engine_config = engine_config_for(self.config)
        remote = (RemoteBA() if self.config.engine.bundle_adjustment == 'node'
                  and engine_config.camera_motion != 'static' else None)
        self.engine = engine = StreamingEngine(engine_config, ba_backend=remote)
        self.path = CameraPath(self.config.outputs.path_length)
        self._engine_statistics: dict[str, object] = engine.statistics
        self.statistics = EstimatorStatistics(self.config.diagnostics.window_s)
        self._previous: StatisticsSnapshot | None = None
        self._pairing = CameraInfoPairing(int(self.config.camera.info_tolerance_s * NS_PER_S),
                                          self.config.camera.fallback)
        self._pairing_lock = threading.Condition()
        self._paired_once = False
        # (message, arrival ns, its RGB image when decoded on arrival for detect_ahead)
        self._slot: LatestFrameSlot[tuple[Any, int, np.ndarray | None]] = LatestFrameSlot()
        self._arrivals: OrderedDict[int, int] = OrderedDict()  # image stamp -> arrival, ns
        self._image_topics: dict[type, str] = {}  # message type -> resolved topic name
        self.outputs = OutputPublishers(self, self.config.outputs, self.config.frames,
                                        self.config.tf,
                                        static_camera=engine.static)
        self._diagnostics = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, 10)
        self._ba_node = (None if remote is None else BANodeClient(
            self, self.config.ba_node, self.config.frames.world_frame_id, remote))
        overrides = QoSOverridingOptions.with_default_policies()
        # rclpy writes a topic's QoS overrides into the profile it is given: one copy per topic.
        for msg_type, topic in ((Image, 'image'), (CompressedImage, 'image/compressed')):
            self._image_topics[msg_type] = self.create_subscription(
                msg_type, topic, self._on_image, copy.copy(qos_profile_sensor_data),
                qos_overriding_options=overrides).topic_name
        self._camera_info_topic = self.create_subscription(
            CameraInfo, 'camera_info', self._on_camera_info, copy.copy(qos_profile_sensor_data),
            qos_overriding_options=overrides).topic_name
        self.create_timer(self.config.diagnostics.period_s, self._publish_diagnostics)
        self._worker = threading.Thread(target=self._run_inference, name='inference',
                                        daemon=True)
        self._worker.start()
        self.get_logger().info(
            f'ready: engine profile {self.config.engine.profile}, {engine.config.mode} on '
            f'{engine.config.device}, hand source {engine.config.hands.source}, camera motion '
            f'{engine.config.camera_motion}, {pacing_text(engine)}, smoothing '
            f'{engine.config.output.smoothing.mode}, bundle adjustment '
            f'{self.config.engine.bundle_adjustment}')
        self._interval_logged = engine.statistics['pacing']['geometry_interval']
        self._lens_provisional = False

    def close(self) -> None:
        """Stop the inference thread and close the engine (call before ``destroy_node``)."""
        self._slot.close()
        self._worker.join()
        self.engine.close()

    def _now_ns(self) -> int:
        """Return the node clock's time, nanoseconds (ROS time; sim time when enabled)."""
        return self.get_clock().now().nanoseconds

    def _on_image(self, msg: Image | CompressedImage) -> None:
        """Keep only the newest image; count the one it replaces as dropped.

        An image out of order is skipped here already, so it never replaces a waiting one.
        Where the engine reads hands ahead, the image is decoded here and its detection
        started (a bad image is left for the inference thread to report).
        """
        now = self._now_ns()
        self.statistics.frame_received(now / NS_PER_S)
        stamp_ns = ns_from_stamp(msg.header.stamp)
        if self._stamp_step(msg, stamp_ns) is StampStep.OUT_OF_ORDER:
            return
        self.engine.observe_input(time.monotonic_ns())  # paced to the rate images arrive at
        rgb = None
        if self.engine.detects_ahead:
            with contextlib.suppress(InputError):
                rgb = decode_image(msg)
                self.engine.detect_ahead(rgb, stamp_ns)
        if self._slot.put((msg, now, rgb)):
            self.statistics.frame_dropped()

    def _stamp_step(self, msg: Image | CompressedImage, stamp_ns: int) -> StampStep:
        """Return how the engine's stream policy takes the image's stamp; count one out of order.

        The warning is throttled (``bad_frame_log_period_s``): however many come, one line per
        period; each one is counted in ``frames_out_of_order``.
        """
        last = self.engine.last_accepted_ns
        step = self.engine.stamp_step(stamp_ns)
        if step is StampStep.OUT_OF_ORDER:
            self.statistics.frame_out_of_order()
            self.get_logger().warning(
                f'{self._image_topics[type(msg)]}: skipping an image stamped {stamp_ns} ns, not '
                f'after the last accepted image stamped {last} ns (out of order or repeated; '
                'counted in frames_out_of_order)',
                throttle_duration_sec=self.config.bad_frame_log_period_s)
        return step

    def _restart_stream(self, msg: Image | CompressedImage, stamp_ns: int) -> None:
        """Start a new stream whose first image is stamped ``stamp_ns`` (inference thread).

        Everything the node keeps per stream starts afresh: the engine (world frame, pose
        track, BA, output stage), the camera path, arrival times, the CameraInfos ahead of the
        new stamp and, with the BA node, the keyframes sent (their late results are refused;
        the BA node starts a new sequence when the keyframe stamps go back).
        """
        last = self.engine.last_accepted_ns
        self.statistics.stream_restarted()
        self.get_logger().warning(
            f'{self._image_topics[type(msg)]}: an image stamped {stamp_ns} ns, more than '
            f'restart_after_s before the last accepted image stamped {last} ns (a '
            'replay loop, a camera restart or a far-future stamp before): a new stream starts '
            'with it and the world frame restarts (counted in stream_restarts)',
            throttle_duration_sec=self.config.bad_frame_log_period_s)
        self.engine.reset()
        self._engine_statistics = self.engine.statistics
        self.path.clear()
        self._arrivals.clear()
        with self._pairing_lock:
            self._pairing.forget_after(stamp_ns)
            self._paired_once = False  # the new stream's first image waits for its CameraInfo
        if self._ba_node is not None:
            self._ba_node.restart()

    def _on_camera_info(self, msg: CameraInfo) -> None:
        """Store a CameraInfo for pairing; a bad one is logged, counted and ignored."""
        try:
            with self._pairing_lock:
                self._pairing.add(msg)
                self._pairing_lock.notify_all()
        except InputError as exc:
            self._bad_frame(f'{self._camera_info_topic}: ignoring a CameraInfo (its images go '
                            f'on with the fallback or predicted intrinsics): {exc}')

    def _bad_frame(self, text: str) -> None:
        """Count and log (throttled) a refused message."""
        self.statistics.frame_bad()
        self.get_logger().warning(text,
                                  throttle_duration_sec=self.config.bad_frame_log_period_s)

    def _run_inference(self) -> None:
        """Take the newest image, run it through the pipeline, publish; until closed.

        After publishing, the engine catches up on the geometry a frame answered first still
        owes (``StreamingEngine.catch_up``): here, or with ``engine.geometry_lag`` >= 1 (2 by
        default) in the engine's worker thread, paused while the next images are processed.
        While no image comes, the BA node's corrections are still applied (a stream that
        paused or ended right after a keyframe gets its refinement).
        """
        while not self._slot.closed:
            item = self._slot.take(TAKE_TIMEOUT_S)
            try:
                if item is None:  # no frame: corrections that came after the last one go in now
                    self._fold_in_corrections()
                else:
                    self._process(*item)
                    self.engine.catch_up()
            except RuntimeError:  # rclpy's RCLError: SIGINT invalidated the context mid-publish
                if self.context.ok():
                    raise
                return

    def _process(self, msg: Image | CompressedImage, arrival_ns: int,
                 rgb: np.ndarray | None) -> None:
        """Decode (unless done on arrival), pair with intrinsics, run the pipeline, publish."""
        stamp_ns = ns_from_stamp(msg.header.stamp)
        step = self._stamp_step(msg, stamp_ns)  # an image may have been accepted since the put
        if step is StampStep.OUT_OF_ORDER:
            return
        if step is StampStep.RESTART:
            self._restart_stream(msg, stamp_ns)
        self._arrivals[stamp_ns] = arrival_ns
        while len(self._arrivals) > ARRIVALS_KEPT:
            self._arrivals.popitem(last=False)
        try:
            rgb = decode_image(msg) if rgb is None else rgb
            choice = self._intrinsics_for(stamp_ns, rgb.shape[1], rgb.shape[0])
            results = self.engine.push(rgb, stamp_ns, choice.intrinsics)
            self.statistics.intrinsics_used(choice.source)
        except InputError as exc:
            self._bad_frame(f'skipping the image stamped {stamp_ns}: {exc}')
            return
        except ModelOutputError as exc:
            self.statistics.frame_bad()
            self.get_logger().error(f'skipping the image stamped {stamp_ns}: {exc}',
                                    throttle_duration_sec=self.config.bad_frame_log_period_s)
            return
        self._engine_statistics = self.engine.statistics
        self._log_pacing()
        camera_frame = (self.config.frames.camera_frame_id or msg.header.frame_id
                        or topics.CAMERA_FRAME_ID)
        for result in results:
            self.path.add(result.frame_index, result.timestamp_ns,
                          PoseFields.from_camera_pose(result.camera_pose), result.pose_version,
                          self.engine.best_pose)
        period_ns = int(self.config.outputs.path_period_s * NS_PER_S)
        for position, result in enumerate(results, start=1):
            # The path holds every result of this push: publish it with the newest one only.
            path = (self.path.poses_due(result.timestamp_ns, period_ns)
                    if position == len(results) else None)
            self.outputs.publish(result, camera_frame, path)
            now = self._now_ns()
            stamp = result.timestamp_ns
            arrival = self._arrivals.get(stamp, now)
            self.statistics.frame_published(now / NS_PER_S, (now - stamp) / NS_PER_S,
                                            (now - arrival) / NS_PER_S, result.tracking)
        if self._ba_node is not None:
            self._ba_node.report_folded_in()
            self._ba_node.send_keyframes(camera_frame)

    def _log_pacing(self) -> None:
        """Log the geometry interval each time the engine's pacing changes it, and the lens."""
        provisional = bool(self._engine_statistics['lens_provisional'])
        if provisional != self._lens_provisional:
            self._lens_provisional = provisional
            self.get_logger().info(
                'lens: provisional while it is estimated beside the stream (frames flagged '
                'provisional_intrinsics)' if provisional else 'lens: settled')
        pacing = self._engine_statistics['pacing']
        if pacing['geometry_interval'] == self._interval_logged:
            return
        self._interval_logged = pacing['geometry_interval']
        self.get_logger().info(
            f"pacing: geometry branch every {pacing['geometry_interval']} frame(s) (a frame "
            f"{pacing['frame_ms']:.0f} ms, the geometry branch {pacing['geometry_ms']:.0f} ms, "
            f"input every {pacing['period_ms']:.0f} ms: "
            f"{100 * pacing['utilisation']:.0f} % of it used)")

    def _fold_in_corrections(self) -> None:
        """Fold the BA node's corrections received since the last frame into the engine."""
        if self._ba_node is not None:
            self.engine.fold_in_ba()
            self._ba_node.report_folded_in()

    def _intrinsics_for(self, stamp_ns: int, width: int, height: int) -> IntrinsicsChoice:
        """Pair an image with its CameraInfo, waiting a little for one that comes just after.

        The first image always waits (its CameraInfo may be the first one); later images wait
        only when the camera publishes CameraInfos.
        """
        with self._pairing_lock:
            if self._pairing.has_infos or not self._paired_once:
                self._paired_once = True
                self._pairing_lock.wait_for(
                    lambda: self._pairing.paired(stamp_ns, width, height) is not None,
                    self.config.camera.info_wait_s)
            return self._pairing.intrinsics_for(stamp_ns, width, height)

    def _publish_diagnostics(self) -> None:
        """Publish the node's figures on /diagnostics."""
        now = self._now_ns()
        snapshot = self.statistics.snapshot(now / NS_PER_S)
        engine_statistics = self._engine_statistics
        if self._ba_node is not None:
            self._ba_node.check()
            engine_statistics = {**engine_statistics, 'ba': self._ba_node.statistics()}
        report = diagnostic_report(snapshot, engine_statistics,
                                   self.config.diagnostics.window_s, self._previous)
        self._previous = snapshot
        self._diagnostics.publish(msg_builders.diagnostic_array_msg(
            now, f'{self.get_name()}: estimator', self.get_fully_qualified_name(), report))


DESCRIPTION: Final = (
    'The InfiniHand estimator: camera images in (image, image/compressed, camera_info),\n'
    'camera pose and world-space hands out (~/hands, ~/camera_pose, ~/camera_path,\n'
    '~/hands/..., /tf).\n\n'
    'Hand source: mediapipe by default (MediaPipe Hands, trained on real photos, lifted to\n'
    'MANO), because this node runs on real camera images and the bundled InfiniHand weights\n'
    'have seen only synthetic images. -p hands.source:=infinihand runs the hand branch of\n'
    'the paper (for trained checkpoints; hands.verify guards it with MediaPipe).\n\n'
    'Engine settings: -p engine.profile:=live (the default: a moving camera), teleop (a\n'
    "fixed camera), offline or synthetic; -p engine.set:='geometry_interval=1 device=cuda'\n"
    'overrides single settings (config/engine.yaml lists them all).')


def pacing_text(engine: StreamingEngine) -> str:
    """Return how often the engine runs its geometry branch, for the start-up log."""
    pacing = engine.statistics['pacing']
    if pacing['paced']:
        limits = engine.config.pacing
        return (f"geometry branch paced from measured cost (every {pacing['geometry_interval']} "
                f'frames to start, up to {limits.max_geometry_interval}, within '
                f'{100 * limits.utilisation:.0f} % of the frame period)')
    return f"geometry every {pacing['geometry_interval']} frames"


def main(args: list[str] | None = None) -> int:
    """Run the node until shut down (``--help``: print the node and its parameters)."""
    parse_command_line('estimator', DESCRIPTION, EstimatorConfig, args)
    return run_node(EstimatorNode, NODE_NAME, args)


if __name__ == '__main__':
    sys.exit(main())
