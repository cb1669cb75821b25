"""Where a frame's time goes: the engine's stages timed on the sample bag, per mode.

    python benchmarks/profile_engine.py [--config config/engine.yaml] [--frames 150]
        [--modes per_frame windowed] [--threads N] [--hand-source mediapipe]
        [--camera-motion static] [--json]

Streams the sample bag's frames (``data/sample_bag``, cycled to ``--frames``) through the
engine in each mode and times every stage (the engine's through ``StreamingEngine.stage_timer``,
the model's and the node's with wall-clock timers wrapped around them): JPEG decode
(the node's ``compressed_msg_to_image`` on the frames re-encoded at quality 90), preparing the
frame (check, letterbox, to a tensor), the hand source's detection when it reads the image (in
the engine's detection thread, beside the model, so not part of the main thread's time), the
geometry branch (aggregator with its frame and global attention blocks and the global blocks'
memory attention, camera head, mask head), the hands (the hand branch with detection from the
masks, the split into per-frame records, the hand source's lifting and gating), engine
bookkeeping (the pose track with its tracker, world placement, the output stage), the depth
head (run on demand inside the bookkeeping, so its time is part of that stage's too) and the
node's publishing (``OutputPublishers.publish`` with the node's output switches, its messages
built and serialised as rclpy's publishers do, nothing sent).
Nested stages are indented under their parent. Per stage it prints milliseconds per frame
(total time / frames) and the calls; the main thread's wall time per frame is printed beside
it, with how many frames ran the depth head and how many skipped the geometry branch (a fixed
camera, or between a moving camera's geometry frames: ``engine.geometry_interval``, which
applies with ``--hand-source mediapipe``). In windowed mode the hand branch runs in the
engine's worker thread, overlapping the next window's geometry, so its stages do not add up to
the wall time. For the global attention it also prints the keys each query frame attends over
(the memory it sees plus itself).
Figures only; nothing is asserted.
"""

import argparse
from collections.abc import Callable
from collections.abc import Iterator
import contextlib
from dataclasses import replace
import json
from pathlib import Path
import threading
import time
from types import SimpleNamespace
from typing import Any
from typing import Final

import cv2
from infinihand_ros.bag.camera_msgs import compressed_msg_to_image
from infinihand_ros.bag.camera_stream import read_camera_frames
from infinihand_ros.core.output_fields import PoseFields
from infinihand_ros.core.units import NS_PER_S
from infinihand_ros.engine import stage_timing
from infinihand_ros.engine.config import CAMERA_MOTIONS
from infinihand_ros.engine.hands.config import HAND_SOURCES
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.output.camera_path import CameraPath
from infinihand_ros.engine.settings import load_engine_config
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.model import infinihand_model
from infinihand_ros.ros.estimator.config import FrameIds
from infinihand_ros.ros.estimator.config import OutputSwitches
from infinihand_ros.ros.estimator.config import TFSettings
from infinihand_ros.ros.estimator.publishers import OutputPublishers
import numpy as np
from rclpy.serialization import serialize_message
from records import add_record_option
from records import Figure
from records import write_record
import torch

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_BAG = ROOT / 'data' / 'sample_bag'
JPEG_QUALITY = 90
MS_PER_S = 1e3
SWITCHES = OutputSwitches()  # the node's defaults: path length and publishing period


class StageClock:
    """Accumulates wall time and calls per stage name (thread-safe)."""

    def __init__(self) -> None:
        """Start with no stages."""
        self._lock = threading.Lock()
        self.seconds: dict[str, float] = {}
        self.calls: dict[str, int] = {}
        self.keys_per_query_frame: list[int] = []

    def add(self, name: str, seconds: float) -> None:
        """Add one call of ``name`` that took ``seconds``."""
        with self._lock:
            self.seconds[name] = self.seconds.get(name, 0.0) + seconds
            self.calls[name] = self.calls.get(name, 0) + 1

    @contextlib.contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time the body as one call of ``name``."""
        start = time.perf_counter()
        try:
            yield
        finally:
            self.add(name, time.perf_counter() - start)

    def timed(self, function: Callable[..., Any], name: str) -> Callable[..., Any]:
        """Return ``function`` wrapped so that each call is timed as ``name``."""
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            with self.stage(name):
                return function(*args, **kwargs)
        return wrapper


def _patch(stack: contextlib.ExitStack, owner: object, attribute: str,
           replacement: Callable[..., Any]) -> None:
    """Set ``owner.attribute`` to ``replacement`` until ``stack`` closes."""
    original = owner.__dict__.get(attribute) if hasattr(owner, '__dict__') else None
    setattr(owner, attribute, replacement)
    if original is None:
        stack.callback(delattr, owner, attribute)
    else:
        stack.callback(setattr, owner, attribute, original)


#: The profile's names of the engine's stages (``StreamingEngine.stage_timer``).
ENGINE_STAGES: Final = {
    stage_timing.STAGE_PREPARE: 'prepare (fit to the model)',
    stage_timing.STAGE_DETECTION: 'hand source detection (own thread)',
    stage_timing.STAGE_HANDS: 'hands',
    stage_timing.STAGE_SPLIT: 'hands/split into frames',
    stage_timing.STAGE_LIFT: 'hands/hand source (lift, gate)',
    stage_timing.STAGE_FINISH: 'engine bookkeeping',
    stage_timing.STAGE_TRACK: 'engine bookkeeping/tracker',
    stage_timing.STAGE_PLACEMENT: 'engine bookkeeping/world placement',
    stage_timing.STAGE_OUTPUT: 'engine bookkeeping/output stage',
}


def _instrument(stack: contextlib.ExitStack, engine: StreamingEngine, clock: StageClock) -> None:
    """Time the engine's stages (its stage timer) and the model's (undone as ``stack`` closes)."""
    engine.stage_timer = lambda stage, seconds: clock.add(ENGINE_STAGES[stage], seconds)
    stack.callback(setattr, engine, 'stage_timer', None)
    model = engine.model
    geometry = model.geometry
    stages: list[tuple[object, str, str]] = [
        (model, 'run_geometry', 'geometry branch'),
        (geometry.aggregator, 'forward', 'geometry branch/aggregator'),
        (geometry.camera_head, 'forward', 'geometry branch/camera head'),
        (geometry.mask_head, 'forward', 'geometry branch/mask head'),
        (geometry.depth_head, 'forward', 'depth head (on demand)'),
        (model, 'run_hands', 'hands/hand branch'),
        (infinihand_model, '_detect_hands', 'hands/hand branch/detection from masks'),
        (model.hand_branch, 'forward', 'hands/hand branch/crops to MANO'),
    ]
    for block in geometry.aggregator.frame_blocks:
        stages.append((block, 'forward', 'geometry branch/aggregator/frame attention blocks'))
    for block in geometry.aggregator.global_blocks:
        stages.append((block, 'forward', 'geometry branch/aggregator/global attention blocks'))
    for owner, attribute, name in stages:
        _patch(stack, owner, attribute, clock.timed(getattr(owner, attribute), name))
    memory = engine.model_stream.aggregator_memory
    attend = memory.attend

    def counted_attend(layer: int, query: torch.Tensor, key: torch.Tensor,
                       value: torch.Tensor) -> torch.Tensor:
        if layer == 0:
            frames = max(1, query.shape[-2] // max(1, memory.tokens_per_frame))
            clock.keys_per_query_frame.extend(memory.keys_per_query_frame(frames))
        return attend(layer, query, key, value)

    _patch(stack, memory, 'attend', clock.timed(
        counted_attend, 'geometry branch/aggregator/global attention blocks/memory attention'))


class _SilentPublisher:
    """A publisher that serialises every message as rclpy's would and sends nothing."""

    def publish(self, message: object) -> None:
        """Serialise ``message`` (``~/hands`` comes serialised already: it goes as it is)."""
        if not isinstance(message, bytes):
            serialize_message(message)


class _SilentNode:
    """The part of an rclpy node ``OutputPublishers`` uses, with silent publishers."""

    def create_publisher(self, *args: object) -> _SilentPublisher:
        """Return a publisher that sends nothing."""
        del args
        return _SilentPublisher()


def _sample_frames() -> list[tuple[bytes, Any]]:
    """Return the sample bag's frames as (JPEG bytes, intrinsics)."""
    frames = []
    for frame in read_camera_frames(SAMPLE_BAG):
        ok, data = cv2.imencode('.jpg', np.ascontiguousarray(frame.rgb[:, :, ::-1]),
                                (cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY))
        if not ok:
            raise RuntimeError('could not encode a sample frame')
        frames.append((data.tobytes(), frame.intrinsics))
    return frames


def _profile(engine: StreamingEngine, frames: list[tuple[bytes, Any]], count: int) -> dict:
    """Stream ``count`` frames through ``engine``; return per-stage ms/frame and the wall."""
    clock = StageClock()
    publishers = OutputPublishers(_SilentNode(), SWITCHES, FrameIds(),
                                  TFSettings(enabled=False))
    path = CameraPath(SWITCHES.path_length)
    results = 0
    with contextlib.ExitStack() as stack:
        _instrument(stack, engine, clock)
        start = time.perf_counter()
        for index in range(count):
            data, intrinsics = frames[index % len(frames)]
            with clock.stage('decode (JPEG)'):
                image = compressed_msg_to_image(SimpleNamespace(data=data, format='jpeg'))
            with clock.stage('push (engine, main thread)'):
                pushed = engine.push(image, index * 100_000_000, intrinsics)
            results += _publish(clock, publishers, path, pushed)
        with clock.stage('push (engine, main thread)'):
            pushed = engine.flush()
        results += _publish(clock, publishers, path, pushed)
        wall = time.perf_counter() - start
    if results != count:
        raise RuntimeError(f'{results} results for {count} frames')
    keys = clock.keys_per_query_frame
    return {'wall_ms_per_frame': MS_PER_S * wall / count, 'fps': count / wall,
            'stages_ms_per_frame': {name: MS_PER_S * seconds / count
                                    for name, seconds in clock.seconds.items()},
            'calls': dict(clock.calls),
            'global_keys_per_query_frame_mean': float(np.mean(keys)) if keys else 0.0}


def _publish(clock: StageClock, publishers: OutputPublishers, path: CameraPath,
             results: list) -> int:
    """Build the node's messages for ``results`` (timed) the way the node does; return count."""
    period_ns = int(SWITCHES.path_period_s * NS_PER_S)
    with clock.stage('publishing (build, serialise)'):
        for position, result in enumerate(results, start=1):
            path.add(result.frame_index, result.timestamp_ns,
                     PoseFields.from_camera_pose(result.camera_pose), result.pose_version)
            publishers.publish(result, 'camera', path.poses_due(result.timestamp_ns, period_ns)
                               if position == len(results) else None)
    return len(results)


def _print(mode: str, figures: dict) -> None:
    """Print one mode's profile as an indented table."""
    print(f'{mode}: {figures["fps"]:.1f} frames/s, wall {figures["wall_ms_per_frame"]:.1f} '
          f'ms/frame; global attention keys per query frame '
          f'{figures["global_keys_per_query_frame_mean"]:.0f}; frames with depth '
          f'{figures["engine"]["frames_with_depth"]}, without geometry '
          f'{figures["engine"]["frames_without_geometry"]} of '
          f'{figures["engine"]["frames_pushed"]}')
    stages = figures['stages_ms_per_frame']
    for name in sorted(stages, key=_stage_order):
        depth = name.count('/')
        label = '  ' * depth + name.rsplit('/', 1)[-1]
        print(f'  {label:52s} {stages[name]:8.2f} ms/frame  {figures["calls"][name]:6d} calls')


_TOP = ('decode (JPEG)', 'push (engine, main thread)', 'hand source detection (own thread)',
        'prepare (fit to the model)',
        'geometry branch', 'hands', 'engine bookkeeping', 'depth head (on demand)',
        'publishing (build, serialise)')


def _stage_order(name: str) -> tuple[int, str]:
    """Sort stages by pipeline order, children right after their parent."""
    top = name.split('/', 1)[0]
    return (_TOP.index(top) if top in _TOP else len(_TOP), name)


def main() -> None:
    """Profile the modes and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--config', type=Path, default=None, help='engine YAML')
    parser.add_argument('--frames', type=int, default=150, help='frames per mode')
    parser.add_argument('--modes', nargs='+', choices=('per_frame', 'windowed'),
                        default=['per_frame', 'windowed'])
    parser.add_argument('--threads', type=int, default=None, help='torch threads (default: '
                        "torch's)")
    parser.add_argument('--hand-source', choices=HAND_SOURCES, default=None,
                        help="engine.hands.source (default: the config's)")
    parser.add_argument('--camera-motion', choices=CAMERA_MOTIONS, default=None,
                        help="engine.camera_motion (default: the config's)")
    parser.add_argument('--json', action='store_true', help='print one JSON line')
    add_record_option(parser)
    args = parser.parse_args()
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    config = load_engine_config(args.config)
    if args.hand_source is not None:
        config = replace(config, hands=replace(config.hands, source=args.hand_source))
    if args.camera_motion is not None:
        config = replace(config, camera_motion=args.camera_motion)
    model = build_model(config)
    frames = _sample_frames()
    figures = {}
    for mode in args.modes:
        with StreamingEngine(replace(config, mode=mode), model) as engine:
            figures[mode] = _profile(engine, frames, args.frames)
            figures[mode]['engine'] = {key: engine.statistics[key] for key in (
                'frames_pushed', 'frames_with_depth', 'frames_without_geometry')}
    setting = (f'hands {config.hands.source}, camera {config.camera_motion}, '
               f'{torch.get_num_threads()} torch threads, sample bag')
    write_record(args.record, 'profile_engine', [
        Figure(f'engine {mode} ({setting})', values['fps'], 'frames/s')
        for mode, values in figures.items()])
    if args.json:
        print(json.dumps(figures))
        return
    print(f'engine {config.model.geometry}/{config.model.hand_branch} on {config.device}, '
          f'hands {config.hands.source}, camera {config.camera_motion}, '
          f'{torch.get_num_threads()} torch threads, {args.frames} sample-bag frames per mode')
    for mode, values in figures.items():
        _print(mode, values)


if __name__ == '__main__':
    main()
