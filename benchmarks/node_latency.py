"""Live estimator figures: output rate, latency and drops with a bag replayed at 10/30 Hz.

    python benchmarks/node_latency.py [--rates 10 30] [--ba none in_process node]
        [--profiles default teleop] [--frames sample|real|real2|ego] [--seconds S]
        [--repeat N] [--load none|busy|both] [--json]

Needs the colcon install (``install/infinihand_ros/lib/infinihand_ros``) and ``source
scripts/env.sh``. For each profile, input rate and BA setting it starts the installed ``estimator``
(with ``engine.bundle_adjustment`` none, in_process, or ``node`` plus the installed
``bundle_adjustment`` node) on a private DDS domain, replays the frames (10 FPS; ``replay --rate
r/10``) and listens in this process to the replayed images and to ``~/camera_pose``. Profiles:
``default`` (the node's defaults: the geometry interval paced from measured cost), ``interval3``
(the defaults with a fixed interval of 3, ``engine.set: geometry_interval=3``), ``lag0`` (the
defaults with the geometry branch's outputs taken in before the next frame, ``engine.set:
geometry_lag=0``, so that it runs in the inference thread), ``lag1`` (taken in a frame late, before
the second frame after it, instead of the node's two frames late: ``engine.set: geometry_lag=1``),
``every_frame`` (the defaults with the geometry branch on every frame, ``engine.set:
geometry_interval=1``), ``teleop`` (``engine.profile: static``, a fixed camera, with the default
MediaPipe hands: the teleoperation case; BA does not apply) and ``teleop_pair`` (the same with
``hands.search_interval: 1``: MediaPipe as it is, one graph following both hands, instead of one
graph per hand side by side). Frames: ``sample``, the first ``--seconds`` of the sample bag
(synthetic, 518x378 JPEG), ``real``, a 15 s crop video panning over a real hand photo from
``../shared/data/real_hands_stills`` (640x480 JPEG with exact CameraInfo;
``synth/photo_streams.py``), or ``real2``, the same video with the photo's half around the hand
beside its mirror image (a real hand of each side in every frame: two-handed teleoperation; its
CameraInfo is the photo's, as the composite is no single camera's image, which the timing does not
depend on), or ``ego``, a real head-mounted clip (``ego4d_stove`` of ``../shared/data/real_ego``,
two hands stirring) played forwards and backwards for 200 frames, scaled to 640 px wide, stamped at
10 Hz, without CameraInfo. ``--load busy`` keeps one core busy with another process during each run
(``both``: each run idle, then busy). Beside the node it times MediaPipe Hands alone (its video
mode as it is, ``hands.search_interval: 1``) on the same decoded frames, one after another in this
process, printed with the node's ratio to it.

Latency is measured as receive time minus the replay's publish time, on this machine's
monotonic clock: the time this process receives an output minus the time it received the image
with the same stamp (shared-memory transport: the image arrives here within a fraction of a
millisecond of its publication). No ``/clock`` is involved. Printed per run: output rate (Hz,
outputs over the span from first to last output), latency p50/p95 (ms) over all outputs, and
apart: p50/p95 after the first 2 s of images and the largest before (the start-up: anchor
frames held back together, the metric scale's warm-up, the first palm search), the node's own
processing time p50/p95 (image arrival to publication, from its /diagnostics), and drops: images
the node received but replaced before inference (``frames_dropped`` of its last /diagnostics), and
images of the segment that never reached the node (``not_received``). With the BA node, the
BA results the estimator applied. Figures only; nothing is asserted. ``--repeat N`` replays the
frames N times in a row with the stamps going on (a scene cut where each copy begins, no stream
restart): figures over a long run, where the start-up weighs less.
"""

import argparse
from collections.abc import Iterator
import contextlib
from dataclasses import asdict
from dataclasses import dataclass
from dataclasses import replace
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from infinihand_ros.bag.camera_msgs import camera_info_to_msg
from infinihand_ros.bag.camera_msgs import compressed_msg_to_image
from infinihand_ros.bag.camera_msgs import image_to_compressed_msg
from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.bag.messages import stamp_from_ns
from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.bag.typestore import CAMERA_INFO_MSG
from infinihand_ros.bag.typestore import COMPRESSED_IMAGE_MSG
from infinihand_ros.core.topics import CAMERA_FRAME_ID
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.engine.hands.config import HandsConfig
from infinihand_ros.engine.hands.mediapipe_detector import MediaPipeDetector
from infinihand_ros.ros.node_process import use_package_dds_profile
from infinihand_ros.synth.photo_streams import crop_stream
import numpy as np
from PIL import Image
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import qos_profile_sensor_data
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer
from sensor_msgs.msg import CompressedImage

ROOT = Path(__file__).resolve().parents[1]
LIB = ROOT / 'install' / 'infinihand_ros' / 'lib' / 'infinihand_ros'
SAMPLE_BAG = ROOT / 'data' / 'sample_bag'
BAG_FPS = 10.0
IMAGE_TOPIC = '/camera/image_raw/compressed'
INFO_TOPIC = '/camera/camera_info'
POSE_TOPIC = '/infinihand_estimator/camera_pose'
REMAPS = ['-r', f'image/compressed:={IMAGE_TOPIC}', '-r', f'camera_info:={INFO_TOPIC}']
#: Node parameters of each profile.
PROFILES = {'default': [], 'interval3': ['-p', "engine.set:='geometry_interval=3'"],
            'lag0': ['-p', "engine.set:='geometry_lag=0'"],
            'lag1': ['-p', "engine.set:='geometry_lag=1'"],
            'every_frame': ['-p', "engine.set:='geometry_interval=1 geometry_lag=0'"],
            'teleop': ['-p', 'engine.profile:=teleop'],
            'teleop_pair': ['-p', 'engine.profile:=teleop', '-p', 'hands.search_interval:=1']}
STILLS = ROOT.parent / 'shared' / 'data' / 'real_hands_stills'
REAL_SECONDS = 15.0
JPEG_QUALITY = 90
READY = 'ready:'
SETTLE_S = 3.0
MS_PER_S = 1e3
#: Outputs of images this soon after the first one are the start-up (anchor frames held back,
#: metric-scale warm-up, first palm search); the steady-state figures leave them out.
START_UP_S = 2.0
EGO_CLIP = ROOT.parent / 'shared' / 'data' / 'real_ego' / 'ego4d_stove'
EGO_FRAMES = 200
EGO_WIDTH = 640
#: Whether another process keeps a core busy, per ``--load``.
LOADS = {'none': (False,), 'busy': (True,), 'both': (False, True)}


@dataclass(frozen=True)
class RunFigures:
    """What one run measured."""

    profile: str
    rate_hz: float
    bundle_adjustment: str
    images: int
    outputs: int
    output_rate_hz: float
    latency_p50_ms: float
    latency_p95_ms: float
    steady_p50_ms: float
    steady_p95_ms: float
    start_up_max_ms: float
    processing_p50_ms: float
    processing_p95_ms: float
    frames_received: int
    frames_dropped: int
    not_received: int
    ba_results_applied: int
    load: str = 'idle'
    pacing: str = ''


def parse_args() -> argparse.Namespace:
    """Parse and check the arguments; exit 2 with one line naming a bad one."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rates', type=float, nargs='+', default=[10.0, 30.0],
                        help='input rates, Hz (the bag is 10 FPS)')
    parser.add_argument('--ba', nargs='+', default=['none', 'in_process', 'node'],
                        choices=['none', 'in_process', 'node'],
                        help="bundle adjustment: none, the engine's worker (the node's "
                        'default) or the BA node')
    parser.add_argument('--profiles', nargs='+', default=list(PROFILES), choices=list(PROFILES),
                        help='default: the node as shipped; lag0, lag1: the geometry branch '
                        'taken in before the next frame, or the one after it '
                        '(engine.set geometry_lag=0, 1; the node takes it in two frames late); '
                        'every_frame: the '
                        'geometry branch on every frame (engine.set geometry_interval=1); teleop: '
                        'a fixed camera (engine.profile teleop) with MediaPipe hands; '
                        'teleop_pair: the same with MediaPipe as it is, one graph for both '
                        'hands (hands.search_interval 1)')
    parser.add_argument('--frames', choices=('sample', 'real', 'real2', 'ego'), default='sample',
                        help='sample: the sample bag; real: a crop video of a real hand photo; '
                        'real2: the same with the photo beside its mirror image (two hands); '
                        'ego: a real head-mounted clip played forwards and backwards')
    parser.add_argument('--load', choices=('none', 'busy', 'both'), default='none',
                        help='busy: another process keeps one core busy during each run; '
                        'both: each run idle, then busy')
    parser.add_argument('--seconds', type=float, default=0.0,
                        help='replay only the first S seconds of the bag (0: all of it)')
    parser.add_argument('--repeat', type=int, default=1,
                        help='replay the frames this many times in a row (stamps going on), '
                        'for figures over a long run')
    parser.add_argument('--json', action='store_true', help='print one JSON line per run')
    args = parser.parse_args()
    if args.repeat < 1:
        parser.error('--repeat must be at least 1')
    if any(rate <= 0 for rate in args.rates):
        parser.error(f'--rates must be > 0, got {args.rates}')
    if args.seconds < 0:
        parser.error(f'--seconds must be >= 0, got {args.seconds}')
    if not (LIB / 'estimator').exists():
        parser.error(f'{LIB / "estimator"} is missing; build with colcon (make build)')
    return args


def write_segment(seconds: float, out: Path) -> int:
    """Copy the camera topics of the bag's first ``seconds`` (0: all) to ``out``; return images."""
    images = 0
    with AnyReader([SAMPLE_BAG], default_typestore=build_typestore()) as reader, \
            Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = [c for c in reader.connections if c.topic in (IMAGE_TOPIC, INFO_TOPIC)]
        added = {c.topic: writer.add_connection(c.topic, c.msgtype, typestore=reader.typestore)
                 for c in connections}
        end = reader.start_time + int(seconds * NS_PER_S) if seconds else None
        for connection, log_time, raw in reader.messages(connections=connections):
            if end is not None and log_time >= end:
                break
            writer.write(added[connection.topic], log_time, raw)
            images += int(connection.topic == IMAGE_TOPIC)
    return images


class Listener:
    """Receive times (monotonic ns) of replayed images and estimator outputs, by stamp."""

    def __init__(self) -> None:
        """Subscribe to the images, the camera poses and /diagnostics."""
        self.node = rclpy.create_node('node_latency_benchmark')
        self.inputs: dict[int, int] = {}
        self.outputs: dict[int, int] = {}
        self.diagnostics: dict[str, str] = {}
        self.node.create_subscription(CompressedImage, IMAGE_TOPIC,
                                      lambda m: self._stamp(self.inputs, m),
                                      qos_profile_sensor_data)
        self.poses = self.node.create_subscription(PoseStamped, POSE_TOPIC,
                                                   lambda m: self._stamp(self.outputs, m), 10)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._diagnostic, 10)
        self._executor = SingleThreadedExecutor()
        self._executor.add_node(self.node)
        self._thread = threading.Thread(target=self._executor.spin, daemon=True)
        self._thread.start()

    def _stamp(self, into: dict[int, int], msg: object) -> None:
        into.setdefault(ns_from_stamp(msg.header.stamp), time.monotonic_ns())

    def _diagnostic(self, msg: object) -> None:
        for status in msg.status:
            if status.name.endswith(': estimator'):
                self.diagnostics = {kv.key: kv.value for kv in status.values}

    def wait_matched(self, timeout_s: float = 20.0) -> None:
        """Wait until the estimator's pose publisher is matched (its first outputs count)."""
        deadline = time.monotonic() + timeout_s
        while self.poses.get_publisher_count() == 0:
            if time.monotonic() > deadline:
                raise RuntimeError(f'no publisher of {POSE_TOPIC} matched in {timeout_s:g} s')
            time.sleep(0.05)

    def close(self) -> None:
        """Stop listening."""
        self._executor.shutdown()
        self.node.destroy_node()


def start(executable: str, args: list[str], log: Path) -> subprocess.Popen:
    """Start an installed executable with its output to ``log``."""
    with open(log, 'wb') as out:
        return subprocess.Popen([str(LIB / executable), *args], stdout=out,
                                stderr=subprocess.STDOUT)


def wait_ready(process: subprocess.Popen, log: Path, timeout_s: float = 180.0) -> None:
    """Wait for a node's ready line; raise RuntimeError with its log if it ends first."""
    deadline = time.monotonic() + timeout_s
    while READY not in log.read_text(errors='replace'):
        if process.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f'{log.name}: not ready\n{log.read_text(errors="replace")}')
        time.sleep(0.2)


def stop(process: subprocess.Popen) -> None:
    """SIGINT a process and wait for it."""
    process.send_signal(signal.SIGINT)
    process.wait(60)


def figures(profile: str, rate_hz: float, ba: str, images: int, listener: Listener
            ) -> RunFigures:
    """Compute one run's figures from what the listener received."""
    first = min(listener.inputs) if listener.inputs else 0
    pairs = {s: (listener.outputs[s] - listener.inputs[s]) / NS_PER_S * MS_PER_S
             for s in listener.outputs if s in listener.inputs}
    start_up = [ms for s, ms in pairs.items() if s - first < START_UP_S * NS_PER_S]
    steady = [ms for s, ms in pairs.items() if s - first >= START_UP_S * NS_PER_S]

    def percentiles(values: list[float]) -> tuple[float, float]:
        if not values:
            return float('nan'), float('nan')
        p50, p95 = np.percentile(values, [50.0, 95.0])
        return float(p50), float(p95)

    times = sorted(listener.outputs.values())
    span_s = (times[-1] - times[0]) / NS_PER_S if len(times) > 1 else 0.0
    values = listener.diagnostics
    received = int(values.get('frames_received', 0))
    return RunFigures(profile, rate_hz, ba, images, len(times),
                      (len(times) - 1) / span_s if span_s else 0.0,
                      *percentiles(list(pairs.values())), *percentiles(steady),
                      max(start_up, default=float('nan')),
                      float(values.get('processing_p50_ms', 'nan')),
                      float(values.get('processing_p95_ms', 'nan')), received,
                      int(values.get('frames_dropped', 0)), images - received,
                      int(values.get('ba_results_applied', 0)),
                      pacing=(f"geometry every {values.get('geometry_interval', '?')} "
                              f"(frame {values.get('frame_ms', 'nan')} ms, geometry "
                              f"{values.get('geometry_ms', 'nan')} ms, "
                              f"utilisation {values.get('utilisation', 'nan')})"))


def repeat_segment(source: Path, out: Path, times: int) -> int:
    """Write ``times`` copies of a segment one after another to ``out``; return the images.

    Each copy's stamps (log times and headers) follow the last copy's by one frame period, so
    the stream goes on without a restart (the scene cuts where a copy begins).
    """
    store = build_typestore()
    with AnyReader([source], default_typestore=store) as reader:
        connections = list(reader.connections)
        messages = [(connection, log_time, reader.deserialize(raw, connection.msgtype))
                    for connection, log_time, raw in reader.messages(connections=connections)]
    stamps = sorted({log_time for connection, log_time, _ in messages
                     if connection.topic == IMAGE_TOPIC})
    period = stamps[1] - stamps[0] if len(stamps) > 1 else NS_PER_S // BAG_FPS
    span = stamps[-1] - stamps[0] + period
    images = 0
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        added = {c.topic: writer.add_connection(c.topic, c.msgtype, typestore=store)
                 for c in connections}
        for copy_index in range(times):
            shift = copy_index * span
            for connection, log_time, message in messages:
                stamp = stamp_from_ns(store, ns_from_stamp(message.header.stamp) + shift)
                shifted = replace(message, header=replace(message.header, stamp=stamp))
                writer.write(added[connection.topic], log_time + shift,
                             store.serialize_cdr(shifted, connection.msgtype))
                images += int(connection.topic == IMAGE_TOPIC)
    return images


def write_real_segment(out: Path, two_hands: bool = False) -> int:
    """Write a crop video over a real hand photo (JPEG images, CameraInfo) to ``out``.

    With ``two_hands`` the photo's half around its hand is put beside its mirror image, so the
    video shows a real hand and its mirror image, a hand of the other side, side by side (the
    CameraInfo stays the photo's).
    """
    frames = list(read_camera_frames(STILLS))
    detector = MediaPipeDetector(HandsConfig(source='mediapipe'))
    try:
        for frame in frames:
            found = detector.detect(frame.rgb, 0)
            detector.reset()
            if len(found) == 1 and found[0].confidence > 0.9:
                break
        else:
            raise RuntimeError(f'no photo in {STILLS} with one clear hand')
    finally:
        detector.close()
    rgb, centre = frame.rgb, found[0].joints_2d.mean(axis=0)
    if two_hands:
        width = rgb.shape[1] // 2
        x0 = int(np.clip(round(centre[0]) - width // 2, 0, rgb.shape[1] - width))
        half = rgb[:, x0:x0 + width]
        rgb = np.ascontiguousarray(np.concatenate([half[:, ::-1], half], axis=1))
        centre = np.array([rgb.shape[1] / 2, centre[1]])
    count = int(REAL_SECONDS * BAG_FPS)
    phase = np.linspace(0.0, 1.0, count)
    centres = centre + np.stack(
        [40 * np.sin(2 * np.pi * phase), 25 * np.cos(2 * np.pi * phase)], axis=1)
    crops = crop_stream(rgb, frame.intrinsics, centres, np.full(count, 480.0),
                        size=(640, 480), fps=BAG_FPS)
    store = build_typestore()
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        image_topic = writer.add_connection(IMAGE_TOPIC, COMPRESSED_IMAGE_MSG, typestore=store)
        info_topic = writer.add_connection(INFO_TOPIC, CAMERA_INFO_MSG, typestore=store)
        for crop in crops:
            stamp = NS_PER_S + crop.timestamp_ns  # the stream starts 1 s after the epoch
            image = image_to_compressed_msg(store, crop.rgb, stamp, CAMERA_FRAME_ID, 'jpeg',
                                            JPEG_QUALITY)
            info = camera_info_to_msg(store, crop.intrinsics, stamp, CAMERA_FRAME_ID)
            writer.write(info_topic, stamp, store.serialize_cdr(info, CAMERA_INFO_MSG))
            writer.write(image_topic, stamp, store.serialize_cdr(image, COMPRESSED_IMAGE_MSG))
    return len(crops)


@dataclass(frozen=True)
class MediaPipeFigures:
    """MediaPipe Hands alone on the segment's frames, one after another."""

    frames: int
    fps: float
    p50_ms: float
    p95_ms: float
    hands_found: int


def mediapipe_alone(segment: Path) -> MediaPipeFigures:
    """Decode the segment's images as the node does and time MediaPipe Hands on each."""
    images = []
    with AnyReader([segment], default_typestore=build_typestore()) as reader:
        connections = [c for c in reader.connections if c.topic == IMAGE_TOPIC]
        for connection, _, raw in reader.messages(connections=connections):
            images.append(compressed_msg_to_image(reader.deserialize(raw, connection.msgtype)))
    detector = MediaPipeDetector(HandsConfig(source='mediapipe', search_interval=1))  # as it is
    times, found = [], 0
    try:
        for index, image in enumerate(images):
            start_s = time.perf_counter()
            found += len(detector.detect(image, index))
            times.append(time.perf_counter() - start_s)
    finally:
        detector.close()
    p50, p95 = np.percentile(times, [50.0, 95.0]) * MS_PER_S
    return MediaPipeFigures(len(images), len(images) / sum(times), float(p50), float(p95),
                            found)


def write_ego_segment(out: Path) -> int:
    """Write ``EGO_FRAMES`` frames of a real head-mounted clip, forwards and backwards, to ``out``.

    The clip's JPEG frames (``../shared/data/real_ego``) are scaled to 640 px wide and stamped at
    10 Hz, with no CameraInfo (the node predicts the lens, as for a camera without one).
    """
    files = sorted((EGO_CLIP / 'frames').glob('*.jpg'))
    if not files:
        raise RuntimeError(f'no frames in {EGO_CLIP / "frames"} (../shared/data is absent)')
    order = files + files[-2:0:-1]
    store = build_typestore()
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        image_topic = writer.add_connection(IMAGE_TOPIC, COMPRESSED_IMAGE_MSG, typestore=store)
        for index in range(EGO_FRAMES):
            rgb = np.asarray(Image.open(order[index % len(order)]).convert('RGB'))
            height = round(rgb.shape[0] * EGO_WIDTH / rgb.shape[1])
            rgb = np.asarray(Image.fromarray(rgb).resize((EGO_WIDTH, height), Image.BILINEAR))
            stamp = NS_PER_S + int(index * NS_PER_S / BAG_FPS)
            image = image_to_compressed_msg(store, rgb, stamp, CAMERA_FRAME_ID, 'jpeg',
                                            JPEG_QUALITY)
            writer.write(image_topic, stamp, store.serialize_cdr(image, COMPRESSED_IMAGE_MSG))
    return EGO_FRAMES


@contextlib.contextmanager
def cpu_load(busy: bool) -> Iterator[None]:
    """Keep one core busy with another process while inside (``busy``), else nothing."""
    if not busy:
        yield
        return
    spinner = subprocess.Popen([sys.executable, '-c', 'while True: pass'])
    try:
        yield
    finally:
        spinner.kill()
        spinner.wait()


def run_once(profile: str, rate_hz: float, ba: str, segment: Path, images: int,
             work: Path) -> RunFigures:
    """Start the nodes, replay the segment at ``rate_hz``, return the figures."""
    # Quoted so the value stays a string whatever it is.
    params = ['--ros-args', '-p', f"engine.bundle_adjustment:='{ba}'", *PROFILES[profile],
              *REMAPS]
    log = work / f'estimator_{profile}_{ba}_{rate_hz:g}.log'
    estimator = start('estimator', params, log)
    helpers = []
    try:
        wait_ready(estimator, log)
        if ba == 'node':
            helpers.append(start('bundle_adjustment', [], work / f'ba_{rate_hz:g}.log'))
            wait_ready(helpers[0], work / f'ba_{rate_hz:g}.log')
        listener = Listener()
        listener.wait_matched()
        replay = start('replay', [str(segment), '--rate', f'{rate_hz / BAG_FPS:g}',
                                  '--wait-for-subscribers', '20'], work / 'replay.log')
        replay.wait()
        time.sleep(SETTLE_S)  # the last inference and a diagnostics period
        listener.close()
        return figures(profile, rate_hz, ba, images, listener)
    finally:
        for process in [estimator, *helpers]:
            stop(process)


def _print(result: RunFigures, alone: MediaPipeFigures, as_json: bool) -> None:
    """Print one run's figures (with its ratios to MediaPipe alone)."""
    rate_ratio = result.output_rate_hz / alone.fps
    latency_ratio = result.latency_p95_ms / alone.p95_ms
    if as_json:
        print(json.dumps({**asdict(result), 'output_rate_to_mediapipe_fps': rate_ratio,
                          'latency_p95_to_mediapipe_p95': latency_ratio}), flush=True)
        return
    print(f'{result.profile:7s} {result.rate_hz:5.1f} Hz in, BA {result.bundle_adjustment:4s}, '
          f'{result.load}: '
          f'{result.outputs}/{result.images} frames out '
          f'({100.0 * result.outputs / result.images:.0f} %) at {result.output_rate_hz:.1f} Hz '
          f'({rate_ratio:.2f}x MediaPipe alone), latency p50 {result.latency_p50_ms:.0f} ms '
          f'p95 {result.latency_p95_ms:.0f} ms (after the first {START_UP_S:g} s: p50 '
          f'{result.steady_p50_ms:.0f} p95 {result.steady_p95_ms:.0f} ms; before: max '
          f'{result.start_up_max_ms:.0f} ms; {latency_ratio:.1f}x MediaPipe p95; node '
          f'processing p50 {result.processing_p50_ms:.0f} p95 {result.processing_p95_ms:.0f} '
          f'ms), dropped '
          f'{result.frames_dropped}, not received {result.not_received}, BA results '
          f'{result.ba_results_applied}; {result.pacing}', flush=True)


def main() -> None:
    """Run every profile, rate and BA setting; print the figures."""
    args = parse_args()
    # A private graph for this run; the nodes started inherit it.
    os.environ['ROS_DOMAIN_ID'] = str(1 + os.getpid() % 100)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    use_package_dds_profile()
    rclpy.init()
    try:
        with tempfile.TemporaryDirectory(prefix='node_latency_') as tmp:
            work = Path(tmp)
            frames = work / 'frames'
            if args.frames == 'sample':
                images = write_segment(args.seconds, frames)
            elif args.frames == 'ego':
                images = write_ego_segment(frames)
            else:
                images = write_real_segment(frames, two_hands=args.frames == 'real2')
            alone = mediapipe_alone(frames)
            segment = frames
            if args.repeat > 1:
                segment = work / 'segment'
                images = repeat_segment(frames, segment, args.repeat)
            print(json.dumps({'mediapipe_alone': asdict(alone)}) if args.json else
                  f'MediaPipe Hands alone on the {alone.frames} {args.frames} frames: '
                  f'{alone.fps:.1f} frames/s, p50 {alone.p50_ms:.1f} ms p95 '
                  f'{alone.p95_ms:.1f} ms, {alone.hands_found} hands found', flush=True)
            for profile in args.profiles:
                for ba in (['none'] if profile.startswith('teleop') else args.ba):
                    for rate in args.rates:
                        for busy in LOADS[args.load]:
                            with cpu_load(busy):
                                result = run_once(profile, rate, ba, segment, images, work)
                            _print(replace(result, load='busy core' if busy else 'idle'),
                                   alone, args.json)
    finally:
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
