"""The one streaming engine: push frames, get per-frame camera poses and world-space hands.

Data flows one way. Each push is prepare, route, run, finish. The frame's stamp goes through the
stream policy (``engine/stream_policy.py``: a stamp out of order is refused, one far back starts
a new stream) and the frame is checked and fitted to the model (``frame_input``); the schedule
(``engine/schedule.py``) picks its route, and the paper's camera-space pass
(``InfiniHandModel``: geometry through the streaming memory, poses, boxes from masks, hand
branch) runs per block. Frame by frame, in order, the camera-space record then goes to the pose
track (its per-frame tracker measures the pose in the image, with the network's pose as prior;
metric scale from the hands; BA corrections), to the bundle-adjustment backend (keyframes;
``engine/ba_backend.py``), its hands are placed in the world once (``engine/world_placement.py``),
with the track's best pose (the identity with ``camera_motion: static``), and the output stage
(``engine/output/``: identity, shared shape, smoothing) gives the result every consumer gets. The
depth head runs only on the frames whose depth is used (a new tracker reference, a metric-scale
sample, a keyframe for BA; every keyframe with ``depth_maps``). A fixed camera whose hands come
from outside the model (``camera_motion: static`` with MediaPipe) skips the geometry branch
wherever the intrinsics are known (given, or fixed from the first frames' predictions): the hand
source is all such a frame needs. A moving camera with such a hand source runs the geometry
branch on every ``geometry_interval``-th frame in per-frame mode (and wherever the tracker needs
depth); every other frame is tracked from the image alone, with the last intrinsics, and carries
no depth. Without BA a frame due for the geometry branch while the tracker holds the camera can
go out before its geometry branch runs (``engine/deferred_geometry.py``, ``catch_up``). A hand
source that reads images (MediaPipe) does so in its own thread, in push order, while the model
runs on the frame. For a fixed camera a live caller can start it earlier, when the image arrives
(``detect_ahead``): the hands of the next frame are then read while the last one is still being
finished and published.

The first ``anchor_frames`` frames are held back and processed together (the paper's anchor
context), in both modes. After that, per-frame mode runs each frame as it arrives; windowed mode
collects ``window`` frames, runs the geometry branch on them in one call and the hand branch in
a worker thread, so the geometry of the next window overlaps the hands of this one (paper Sec.
4.4). At most one window is in the worker: the next one waits for it (bounded memory). Attention
inside a window is causal, so both modes give the same per-frame results.

Threading contract: one caller at a time. ``push``, ``flush``, ``reset``, ``catch_up`` and
``close`` raise ``EngineStateError`` when called while another thread is inside one of them, and
after ``close()``; nothing is consumed then. ``detect_ahead`` and ``stamp_step`` alone may be
called from another thread (an image callback) while they run. ``stage_timer``, when set, is
called with each timed stage (``STAGES``) and its seconds, from the thread that ran it.
"""

from collections import deque
from collections.abc import Callable
from collections.abc import Iterator
from collections.abc import Sequence
from concurrent.futures import Future
from concurrent.futures import ThreadPoolExecutor
import contextlib
import dataclasses
import threading
import time
from typing import Final

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import EngineStateError
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.errors import ModelOutputError
from infinihand_ros.engine.ba_backend import BABackend
from infinihand_ros.engine.ba_backend import keyframe_input
from infinihand_ros.engine.ba_in_process import InProcessBA
from infinihand_ros.engine.camera_space import CameraSpaceFrame
from infinihand_ros.engine.camera_space import depth_ratios
from infinihand_ros.engine.camera_space import PreparedFrame
from infinihand_ros.engine.camera_space import split_frames
from infinihand_ros.engine.camera_space import split_geometry
from infinihand_ros.engine.camera_space import tracking_view
from infinihand_ros.engine.camera_space import with_hand_boxes
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.config import load_engine_config
from infinihand_ros.engine.deferred_geometry import DeferredGeometry
from infinihand_ros.engine.frame_input import check_image
from infinihand_ros.engine.frame_input import check_intrinsics
from infinihand_ros.engine.frame_input import fit_image
from infinihand_ros.engine.hands.reader import HandReader
from infinihand_ros.engine.hands.source import build_hand_source
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.model_builder import InfiniHandModel
from infinihand_ros.engine.output.stage import OutputStage
from infinihand_ros.engine.pose_track import PoseTrack
from infinihand_ros.engine.schedule import FrameSituation
from infinihand_ros.engine.schedule import Route
from infinihand_ros.engine.schedule import route
from infinihand_ros.engine.stream_lens import given_intrinsics
from infinihand_ros.engine.stream_lens import StreamLens
from infinihand_ros.engine.stream_policy import StreamPolicy
from infinihand_ros.engine.timestamps import check_timestamp
from infinihand_ros.engine.timestamps import StampStep
from infinihand_ros.engine.world_placement import WorldPlacement
from infinihand_ros.model.geometry_model import cpu_bf16_supported
from infinihand_ros.model.geometry_model import GeometryOutput
from infinihand_ros.model.geometry_stream import GeometryStream
from infinihand_ros.model.infinihand_model import CameraSpaceOutput
from infinihand_ros.model.io.bundled import hand_depth_correction
from infinihand_ros.model.io.bundled import resolve_checkpoint
import numpy as np
import torch

#: The stages ``stage_timer`` is told of (a child after its parent's name and '/'): checking
#: and fitting a frame; the hand source reading an image (in its own thread, beside the model);
#: a block's hands (the hand branch where it is used, the split into per-frame records, the
#: hand source's lifting and gating); finishing a frame (pose track, world placement, output
#: stage). The model's own parts are timed on ``StreamingEngine.model``.
STAGE_PREPARE: Final = 'prepare'
STAGE_DETECTION: Final = 'hand detection'
STAGE_HANDS: Final = 'hands'
STAGE_SPLIT: Final = 'hands/split into frames'
STAGE_LIFT: Final = 'hands/hand source'
STAGE_FINISH: Final = 'finish'
STAGE_TRACK: Final = 'finish/pose track'
STAGE_PLACEMENT: Final = 'finish/world placement'
STAGE_OUTPUT: Final = 'finish/output stage'
STAGES: Final = (STAGE_PREPARE, STAGE_DETECTION, STAGE_HANDS, STAGE_SPLIT, STAGE_LIFT,
                 STAGE_FINISH, STAGE_TRACK, STAGE_PLACEMENT, STAGE_OUTPUT)


class StreamingEngine:
    """Frames in (RGB uint8, stamp, optional intrinsics), ``FrameResult``s out, in order.

    Attributes:
        stage_timer: None, or called with (stage name, seconds) after each timed stage
            (``STAGES``), from the thread that ran it; for profiling.

    """

    def __init__(self, config: EngineConfig | None = None,
                 model: InfiniHandModel | None = None,
                 ba_backend: BABackend | None = None) -> None:
        """Build the engine (and its model, unless one is given) from ``config``.

        Args:
            config: the engine config (``config/engine.yaml`` if None).
            model: a built model to use instead of building one from ``config``.
            ba_backend: where keyframes go for bundle adjustment; None: an ``InProcessBA``
                when ``config.bundle_adjustment`` is set, else no BA. Not with
                ``camera_motion: static`` (a fixed camera needs no BA).

        Raises:
            ConfigError: for a BA backend with ``camera_motion: static``.

        """
        self.config = config or load_engine_config()
        self.static = self.config.camera_motion == 'static'
        self._tracking = self.config.tracker.enabled and not self.static  # images to track
        if ba_backend is not None and self.static:
            raise ConfigError('engine.camera_motion: static takes no bundle-adjustment backend '
                              '(a fixed camera is the world frame)')
        self.model = model or build_model(self.config)
        self.stage_timer: Callable[[str, float], None] | None = None
        self._scale_correction = _scale_correction(self.config)
        self._output = OutputStage(self.config.output, self.model.hand_branch.hand_models)
        self._hand_source = build_hand_source(self.config.hands,
                                              self.model.hand_branch.hand_models)
        if ba_backend is None and self.config.bundle_adjustment is not None and not self.static:
            ba_backend = InProcessBA(self.config.bundle_adjustment,
                                     self.config.pose_track.capacity)
        self._ba = ba_backend
        self._placement = WorldPlacement(self.static, raw_poses=ba_backend is not None)
        pool = (self.config.bundle_adjustment or BAConfig()).pool
        self._ba_interval_ns = round(1e9 * pool.min_interval_s)
        self._ba_last_ns: int | None = None  # stamp of the last keyframe offered to BA
        self._anchor_frames = self.model.geometry.config.memory.anchor_frames
        detection = self.config.detection
        self._detection = self.model.hand_detection(detection.presence_threshold,
                                                    detection.fov_range_deg,
                                                    detection.peak_region,
                                                    detection.region_join_px)
        self._device = next(self.model.parameters()).device
        self._cpu_bf16 = (self.config.cpu_precision == 'auto' and self._device.type == 'cpu'
                          and cpu_bf16_supported())
        self._decoder = (ThreadPoolExecutor(max_workers=1, thread_name_prefix='hand_decode')
                         if self.config.mode == 'windowed' else None)
        # The hand source reads each image in its own thread, beside the model (in order).
        self._reader = (HandReader(self._hand_source, lambda: self._stage(STAGE_DETECTION))
                        if self._hand_source.needs_image else None)
        # The geometry branch of a frame answered first (catch_up, or the next call).
        geometry = self.model.geometry
        self._deferred = DeferredGeometry(
            self._geometry_only, lambda: (*geometry.aggregator.frame_blocks,
                                          *geometry.aggregator.global_blocks,
                                          geometry.depth_head), self.config.geometry_lag)
        self._policy = StreamPolicy(self.config.restart_after_s)
        self._lens = StreamLens(self.config.lens_frames, self.static,
                                self._hand_source.uses_hand_branch)
        self._guard = threading.Lock()
        self._closed = False
        self._start_sequence()

    def _start_sequence(self) -> None:
        """Reset every per-sequence state (memories, counters, track, BA)."""
        self._stream = self.model.new_stream()
        self._pending: list[PreparedFrame] = []
        self._decoding: deque[Future] = deque()
        self._frames_pushed = 0
        self._policy.accept(None)
        self._accepted_stamp: int | None = None  # last stamp of a block the model accepted
        self._source_size: tuple[int, int] | None = None  # (width, height) of the stream
        self._lens.reset()
        self._counts = {'frames_with_depth': 0, 'frames_without_geometry': 0,
                        'geometry_failures': 0}
        # (index, source intrinsics, model-input intrinsics) of the last geometry frame
        self._geometry_seen: tuple[int, Intrinsics, Intrinsics] | None = None
        self._deferred.reset()
        ba = self.config.bundle_adjustment
        blend_s = (self.config.pose_track.correction_blend_s if ba is None
                   else ba.corrections.blend_s)
        self.pose_track = PoseTrack(self.config.pose_track, self.config.metric_scale, blend_s,
                                    self.config.tracker)
        self._output.reset()

    @property
    def statistics(self) -> dict[str, object]:
        """Return frames pushed, windows decoding, scale, pose version, tracker and BA figures.

        ``frames_with_depth`` counts the frames whose depth the depth head computed,
        ``frames_without_geometry`` those that went on without the geometry branch (a fixed
        camera's, or a moving camera's between geometry frames: ``geometry_interval``).
        ``frames_out_of_order`` and ``stream_restarts`` count the pushes the stream policy
        refused or that started a new stream, since the engine was built.
        """
        estimate = self.pose_track.scale_estimate()
        return {'frames_pushed': self._frames_pushed, **self._counts,
                'windows_in_flight': sum(not future.done() for future in self._decoding),
                'metric_scale': self.pose_track.scale,
                'metric_scale_estimate': estimate.scale,
                'metric_scale_uncertainty': estimate.uncertainty,
                'metric_scale_state': self.pose_track.scale_state,
                'metric_scale_correction': self._scale_correction,
                'pose_version': self.pose_track.version,
                'tracker': self.pose_track.tracker.statistics(),
                'ba': None if self._ba is None else self._ba.statistics(),
                'hands': self._hand_source.statistics(),
                'frames_out_of_order': self._policy.out_of_order,
                'stream_restarts': self._policy.restarts}

    @property
    def model_stream(self) -> GeometryStream:
        """Return the model's streaming state (memories) of the current stream, to inspect."""
        return self._stream

    def stamp_step(self, timestamp_ns: int) -> StampStep:
        """Return how ``push`` takes a frame stamped ``timestamp_ns`` now; changes nothing.

        ``NEXT``: it continues the stream; ``OUT_OF_ORDER``: not after the last accepted
        frame (late or repeated), refused; ``RESTART``: more than ``restart_after_s`` before
        it, a new stream starts with it. Safe from any thread (an image callback), for a
        caller that resets what it keeps per stream (or skips the image) before it pushes.
        """
        return self._policy.step(timestamp_ns)

    def push(self, image: np.ndarray, timestamp_ns: int,
             intrinsics: Intrinsics | None = None) -> list[FrameResult]:
        """Add one frame; return the results that are ready (possibly none, possibly several).

        A frame stamped more than ``restart_after_s`` before the last accepted one starts a
        new stream (as ``reset()``; counted in ``statistics['stream_restarts']``) and is its
        first frame.

        Args:
            image: (H, W, 3) uint8 RGB (the same size for the whole stream).
            timestamp_ns: the image's stamp, integer nanoseconds, increasing; copied to its
                result.
            intrinsics: the camera's intrinsics for this image size, or None to use the
                model's predicted field of view.

        Raises:
            InputError: for a bad image, stamp or intrinsics, and for a stamp out of order
                (counted in ``statistics['frames_out_of_order']``); the stream is left
                unchanged.
            ModelOutputError: when the network's outputs are not finite (names the checkpoint;
                the frames of that block are not added to the stream).
            EngineStateError: after ``close()`` or when another thread is inside the engine.

        """
        with self._exclusive():
            frame = self._prepare(image, timestamp_ns, intrinsics)
            self._settle_owed(frame)
            with self._deferred.holding():
                self._run(self._route(frame), frame, image)
                return self._collect(wait=False)

    @property
    def detects_ahead(self) -> bool:
        """Return whether ``detect_ahead`` starts anything (a fixed camera, MediaPipe hands)."""
        return self.static and self._reader is not None

    def detect_ahead(self, image: np.ndarray, timestamp_ns: int) -> bool:
        """Start reading the hands of an image that will be pushed next; return whether it did.

        For a live caller with a fixed camera (``detects_ahead``): call it when the image
        arrives, from any thread, then ``push`` it as usual; its hand source's detection has
        been running since (in order with the other images'). Detections of images never
        pushed (replaced by newer ones) are dropped at the next push. An image not newer than
        every image pushed or read ahead, or any after ``close()``, is not started (False).
        """
        if not self.detects_ahead or self._closed:
            return False
        try:
            image = check_image(image)
        except InputError:
            return False  # push reports it
        return self._reader.read_ahead(image, timestamp_ns, self._frames_pushed,
                                       self._policy.last_ns)

    def catch_up(self) -> None:
        """Run or start the geometry branch a frame whose result went out first owes (if any).

        For a live caller, right after publishing a result. Where the next frame would take
        its outputs in, it runs (or, started earlier, is waited for) here, so the next frame
        does not wait for it; with ``geometry_lag`` >= 1, right after the frame it belongs to, it
        starts in a worker thread instead, held while a frame is being pushed, so that
        the next frame's answer does not wait for it either. Without catch_up the call that
        needs it runs it. Results are the same either way.

        Raises:
            EngineStateError: after ``close()`` or when another thread is inside the engine.

        """
        with self._exclusive():
            if not self._deferred.startable:
                return
            if self._deferred.late(self._frames_pushed):
                self._pay_geometry()  # the next frame takes it in
                return
            self._deferred.start()

    def flush(self) -> list[FrameResult]:
        """Process every frame still held back and return all remaining results.

        Meant for the end of a stream. Flushing during the anchor frames processes the anchors
        held so far as an anchor block of their own; frames pushed afterwards complete the
        anchors in further blocks, so their results differ from those of an unflushed stream.

        Raises:
            EngineStateError: after ``close()`` or when another thread is inside the engine.

        """
        with self._exclusive():
            self._pay_geometry()
            if self._pending:
                self._run_block()
            return self._collect(wait=True)

    def refined(self, results: Sequence[FrameResult],
                timeout_s: float | None = None) -> list[FrameResult]:
        """Return ``results`` on the final trajectory, for offline runs (after ``flush()``).

        Waits for the BA calls still queued (all of them with ``ba.worker.when_behind: wait``;
        at most ``timeout_s``), then gives every frame the pose the track holds now: all BA
        corrections, none blended in, and the final metric scale, with its hands and depth
        placed again, and ``ba_failed`` where the frame's last BA call failed. Live results are
        what was known when each frame was published; these are what is known at the end.
        Without BA only the scale changes. Frames older than the track's
        ``pose_track.capacity`` are returned unchanged.

        Raises:
            EngineStateError: after ``close()`` or when another thread is inside the engine.

        """
        with self._exclusive():
            self._pay_geometry()
            failed: frozenset[int] = frozenset()
            if self._ba is not None:
                self._ba.settle(self.pose_track, timeout_s)
                failed = self._ba.failed_frames()
            return [self._on_final_trajectory(result, failed) for result in results]

    def _on_final_trajectory(self, result: FrameResult,
                             ba_failed: frozenset[int]) -> FrameResult:
        """Return ``result`` placed with the track's current (not live) pose and scale."""
        try:
            best = self.pose_track.best(result.frame_index, live=False)
        except KeyError:  # no longer in the track
            return result
        return self._placement.on_final_trajectory(result, best,
                                                   result.frame_index in ba_failed)

    def fold_in_ba(self) -> None:
        """Fold finished bundle-adjustment results into the pose track now (between frames).

        Each push does it before posing its frames; call this while no frame comes (a stream
        that paused right after a keyframe gets its refinement, e.g. for a refreshed path).

        Raises:
            EngineStateError: after ``close()`` or when another thread is inside the engine.

        """
        with self._exclusive():
            if self._ba is not None:
                self._ba.fold_in(self.pose_track)

    def best_pose(self, frame_index: int) -> CameraPose | None:
        """Return a frame's current best camera pose (not blended), None once it left the track.

        With ``camera_motion: static`` every frame's pose is the identity. Read-only; safe
        between calls of the engine's caller.
        """
        if self.static:
            return CameraPose.identity()
        try:
            return self.pose_track.best(frame_index, live=False).camera_pose
        except KeyError:
            return None

    def reset(self) -> None:
        """Start a new sequence: drop held-back frames, memories, the pose track and BA."""
        with self._exclusive():
            self._restart()

    def close(self) -> None:
        """Stop the hand detection and decoding workers and the BA worker; idempotent."""
        with self._guard:
            if self._closed:
                return
            self._closed = True
            self._drain()
            if self._decoder is not None:
                self._decoder.shutdown(wait=True)
            if self._reader is not None:
                self._reader.close()
            self._deferred.close()
            if self._ba is not None:
                self._ba.close()
            self._hand_source.close()

    def __enter__(self) -> 'StreamingEngine':
        """Return the engine."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Close the engine."""
        self.close()

    @contextlib.contextmanager
    def _exclusive(self) -> Iterator[None]:
        """Hold the engine for one call; refuse concurrent callers and a closed engine."""
        if not self._guard.acquire(blocking=False):
            raise EngineStateError('StreamingEngine: called from two threads at once; the engine '
                                   'serves one caller at a time (serialise the calls)')
        try:
            if self._closed:
                raise EngineStateError('StreamingEngine: used after close(); build a new engine')
            yield
        finally:
            self._guard.release()

    def _stage(self, name: str) -> contextlib.AbstractContextManager[None]:
        """Return a context that tells ``stage_timer`` (if set) how long its body took."""
        timer = self.stage_timer
        return contextlib.nullcontext() if timer is None else _timed(timer, name)

    def _restart(self) -> None:
        """Start a new sequence (``reset``, from inside a call)."""
        self._drain()
        if self._ba is not None:
            self._ba.reset()
            self._ba_last_ns = None
        if self._reader is None:
            self._hand_source.reset()
        else:  # in its thread: a detection started ahead meanwhile may be running there
            self._reader.reset_source()
        self._start_sequence()

    def _prepare(self, image: np.ndarray, timestamp_ns: int,
                 intrinsics: Intrinsics | None) -> PreparedFrame:
        """Take a frame into the stream: its stamp by the stream policy, checked and fitted.

        A stamp far back starts a new stream first (``restart_after_s``; not for a bad image
        or intrinsics). Raises before anything else changes.
        """
        stamp = check_timestamp(timestamp_ns, None)
        if self._policy.step(stamp) is StampStep.RESTART:
            check_intrinsics(intrinsics, check_image(image))  # a bad frame restarts nothing
        if self._policy.admit(stamp) is StampStep.RESTART:
            self._restart()
        with self._stage(STAGE_PREPARE):
            frame = self._fitted(image, stamp, intrinsics)
        self._frames_pushed += 1
        self._policy.accept(frame.timestamp_ns)
        return frame

    def _fitted(self, image: np.ndarray, timestamp_ns: int,
                intrinsics: Intrinsics | None) -> PreparedFrame:
        """Check a frame and fit it to the model size (raises before any state changes).

        A frame that goes on without the geometry branch (``_skips_geometry``) is not fitted:
        its ``pixels`` and ``mapping`` are None.
        """
        stamp = check_timestamp(timestamp_ns, self._policy.last_ns)
        image = check_image(image)
        intrinsics = check_intrinsics(intrinsics, image) or self._lens.fixed
        size = (image.shape[1], image.shape[0])
        if self._source_size not in (None, size):
            raise InputError(f"image: {size[0]}x{size[1]} px, but this stream's frames are "
                             f'{self._source_size[0]}x{self._source_size[1]} px; keep one image '
                             'size per stream (resize the frames) or reset() between streams')
        pixels = mapping = None
        if not self._skips_geometry(intrinsics):
            geometry = self.model.geometry.config
            fitted, mapping = fit_image(image, geometry.preprocessing, geometry.aggregator)
            pixels = torch.from_numpy(fitted).to(self._device).permute(2, 0, 1).float() / 255.0
        self._source_size = size
        index = self._frames_pushed
        after_anchors = index - self._anchor_frames
        keyframe = after_anchors < 0 or after_anchors % self.config.keyframe_interval == 0
        detections = (None if self._reader is None
                      else self._reader.read(image, stamp, index))
        return PreparedFrame(index, stamp, pixels, mapping, intrinsics, keyframe, None,
                             detections)

    def _skips_geometry(self, intrinsics: Intrinsics | None) -> bool:
        """Return whether a frame with these given intrinsics goes on without the model.

        A fixed camera whose hands come from outside the model needs the geometry branch only
        for intrinsics: not when they are given, or once the first frames' predictions fixed
        them (``lens_frames``). Frames never overtake held-back ones.
        """
        return (self.static and not self._hand_source.uses_hand_branch and not self._pending
                and intrinsics is not None)

    def _settle_owed(self, frame: PreparedFrame) -> None:
        """Take in the owed geometry before ``frame`` where it is due (the gate still open)."""
        tracker = self.pose_track.tracker
        if self._deferred.due(frame.index, tracker.needs_depth and tracker.lost,
                              lambda: (self.pose_track.scale_state == 'warmup'
                                       and bool(frame.found().hands))):
            self._pay_geometry()  # this may wait for the worker

    def _route(self, frame: PreparedFrame) -> Route:
        """Return how a checked frame goes on (``schedule.route`` on its situation)."""
        seen, owed = self._geometry_seen, self._deferred.owed_index
        tracker = self.pose_track.tracker
        since = None if seen is None else frame.index - (seen[0] if owed is None else owed)
        situation = FrameSituation(
            fitted=frame.pixels is not None, per_frame=self.config.mode == 'per_frame',
            geometry_interval=self.config.geometry_interval, tracking=self._tracking,
            hand_branch=self._hand_source.uses_hand_branch, held_back=bool(self._pending),
            in_anchors=frame.index < self._anchor_frames, frames_since_geometry=since,
            owed=owed is not None, owed_failed=self._deferred.failed,
            tracker_needs_depth=tracker.needs_depth, tracker_lost=tracker.lost,
            scale_warmup=self.pose_track.scale_state == 'warmup',
            bundle_adjustment=self._ba is not None)
        return route(situation, lambda: bool(frame.found().hands))

    def _run(self, way: Route, frame: PreparedFrame, image: np.ndarray) -> None:
        """Run a frame the way it goes: queue its record, or hold it back for its block."""
        if way is Route.GEOMETRY:
            if self._ba is not None and frame.keyframe:  # BA reads the keyframe's image
                frame = dataclasses.replace(frame, source_image=image.copy())
            self._pending.append(frame)
            if len(self._pending) >= self._block_size():
                self._run_block()
            return
        self._accepted_stamp = frame.timestamp_ns
        if way is Route.STATIC:  # no model input: the geometry branch is not needed
            self._decoding.append(_done(self._without_geometry(frame)))
            return
        if way is Route.TRACKED:  # enters no streaming memory
            frame = dataclasses.replace(frame, keyframe=False)
            self._counts['frames_without_geometry'] += 1
        record = self._tracked_only(frame)
        self._decoding.append(_done([record]))
        if way is Route.TRACKED_FIRST:
            self._deferred.owe(record)

    def _without_geometry(self, frame: PreparedFrame) -> list[CameraSpaceFrame]:
        """Return a fixed camera's frame record with its source's hands, no model run."""
        self._counts['frames_without_geometry'] += 1
        with self._stage(STAGE_LIFT):
            hands = self._hand_source.camera_hands(frame.found(), (), frame.intrinsics)
        return [CameraSpaceFrame(frame, np.eye(4), frame.intrinsics, hands, None, None)]

    def _tracked_only(self, frame: PreparedFrame) -> CameraSpaceFrame:
        """Return a moving camera's frame record without the geometry branch: no network pose."""
        _, intrinsics, model_intrinsics = self._geometry_seen
        if frame.intrinsics is not None:
            intrinsics = frame.intrinsics
            model_intrinsics = frame.mapping.intrinsics_to_model(frame.intrinsics)
        size = tuple(frame.pixels.shape[-2:])
        view = tracking_view(frame, None, model_intrinsics.matrix(), size)
        with self._stage(STAGE_LIFT):
            hands = self._hand_source.camera_hands(frame.found(), (), intrinsics)
        return CameraSpaceFrame(frame, None, intrinsics, hands, None, view)

    def _geometry_only(self, frame: PreparedFrame) -> CameraSpaceFrame:
        """Run the geometry branch alone on a frame answered first; return its record."""
        intrinsics, known = given_intrinsics([frame])
        with torch.inference_mode():
            geometry, poses, used = self.model.run_geometry(
                frame.pixels[None, None], self._stream, [frame.keyframe], intrinsics, known,
                self._detection, self._cpu_bf16, masks=False, depth=False)
        return split_geometry(geometry, poses, used, [frame], self.model.geometry)[0]

    def _pay_geometry(self) -> None:
        """Take in the geometry branch of the frame that went out before it (``tracked_first``).

        Waits for its run in the worker thread (``catch_up``), or runs it here. The frame has
        entered the streaming memory; the pose track takes its network pose and depth
        (``PoseTrack.absorb``, with the tracker as it was right after the frame), its hands are
        metric-scale samples (the frames between give none) and its intrinsics hold for the
        frames after it. Non-finite outputs leave the memory as it was and are counted
        (``geometry_failures``); the next frame then runs the geometry branch first (where a
        failure raises ``ModelOutputError``).
        """
        try:
            paid = self._deferred.settle()
        except ModelOutputError:
            self._counts['geometry_failures'] += 1
            return
        if paid is None:
            return
        owed, record = paid
        frame = owed.record.frame
        record = dataclasses.replace(record, hands=owed.record.hands,
                                     view=with_hand_boxes(record.view, frame, owed.record.hands))
        self.pose_track.absorb(frame.index, record.T_raw, record.view, owed.moment)
        self._geometry_seen = (frame.index, record.intrinsics, record.view.intrinsics)
        self.pose_track.observe_scale(*self._scale_samples(record, True))
        if record.depth.computed:
            self._counts['frames_with_depth'] += 1

    def _block_size(self) -> int:
        """Return how many frames the next block needs."""
        first_pending = self._frames_pushed - len(self._pending)
        if first_pending < self._anchor_frames:
            return self._anchor_frames - first_pending
        return self.config.window if self.config.mode == 'windowed' else 1

    def _run_block(self) -> None:
        """Run the geometry branch on the held-back frames and queue (or do) the hand branch."""
        frames, self._pending = self._pending, []
        images = torch.stack([frame.pixels for frame in frames])[None]
        intrinsics, known = given_intrinsics(frames)
        try:
            with torch.inference_mode():
                geometry, poses, used = self.model.run_geometry(
                    images, self._stream, [frame.keyframe for frame in frames], intrinsics,
                    known, self._detection, self._cpu_bf16,
                    masks=self._hand_source.uses_hand_branch, depth=False)
        except ModelOutputError as exc:  # the block's frames were not added: forget them
            self._frames_pushed -= len(frames)
            self._policy.accept(self._accepted_stamp)
            raise ModelOutputError(f'{self._checkpoint_name()}: {exc}') from exc
        self._accepted_stamp = frames[-1].timestamp_ns
        self._deferred.failed = False
        used = self._lens.hold(frames, used)
        if self._decoder is None:
            future: Future = _done(self._hands(images, geometry, poses, used, frames))
        else:
            for in_flight in self._decoding:  # back-pressure: one window in the worker
                in_flight.exception()  # waits; its results are collected below
            future = self._decoder.submit(self._hands, images, geometry, poses, used, frames)
        self._decoding.append(future)

    def _hands(self, images: torch.Tensor, geometry: GeometryOutput, poses: torch.Tensor,
               used: torch.Tensor, frames: list[PreparedFrame]) -> list[CameraSpaceFrame]:
        """Find a block's hands with the hand source; split it into per-frame records."""
        with self._stage(STAGE_HANDS):
            source = self._hand_source
            branch = self.model.geometry
            with torch.inference_mode():
                if source.uses_hand_branch:
                    output: CameraSpaceOutput = self.model.run_hands(
                        images, geometry, poses, used, None, self._detection)
                    with self._stage(STAGE_SPLIT):
                        records = split_frames(output, frames, branch, self._tracking)
                else:
                    with self._stage(STAGE_SPLIT):
                        records = split_geometry(geometry, poses, used, frames, branch,
                                                 self._tracking)
            return [dataclasses.replace(record, hands=self._lift(record)) for record in records]

    def _lift(self, record: CameraSpaceFrame) -> tuple[HandState, ...]:
        """Return the hand source's camera-space hands of a frame's record (timed)."""
        with self._stage(STAGE_LIFT):
            return self._hand_source.camera_hands(record.frame.found(), record.hands,
                                                  record.intrinsics)

    def _collect(self, wait: bool) -> list[FrameResult]:
        """Return finished results in order; wait for all of them when ``wait``."""
        results: list[FrameResult] = []
        while self._decoding and (wait or self._decoding[0].done()):
            for record in self._decoding.popleft().result():
                with self._stage(STAGE_FINISH):
                    results.append(self._finish(record))
        return results

    def _drain(self) -> None:
        """Wait for queued hand detection and decoding and drop their results (reset, close)."""
        while self._decoding:
            self._decoding.popleft().exception()
        self._pending.clear()
        self._deferred.drain()
        if self._reader is not None:
            self._reader.drain()

    def _finish(self, record: CameraSpaceFrame) -> FrameResult:
        """Track the frame's pose, feed BA, place its hands in the world: its final result."""
        frame = record.frame
        track = self.pose_track
        view = (None if record.view is None
                else with_hand_boxes(record.view, frame, record.hands))
        with self._stage(STAGE_TRACK):
            state = track.add(frame.index, frame.timestamp_ns, record.T_raw, view)
        self._deferred.finished(record, track.tracker.moment)
        if record.T_raw is not None and view is not None:
            self._geometry_seen = (frame.index, record.intrinsics, view.intrinsics)
        if frame.found().scene_cut or state == 'reinitialised':
            self._output.new_scene()
        to_ba = (self._ba is not None and frame.keyframe and frame.source_image is not None
                 and record.depth is not None
                 and (self._ba_last_ns is None
                      or frame.timestamp_ns - self._ba_last_ns >= self._ba_interval_ns))
        kept = record.depth is not None and frame.keyframe and (to_ba or self.config.depth_maps)
        with self._stage(STAGE_TRACK):
            track.observe_scale(*self._scale_samples(record, kept))
        self._lens.collect(record)
        depth = (frame.mapping.map_to_source(record.depth.model()) * track.scale if kept
                 else None)
        if record.depth is not None and record.depth.computed:
            self._counts['frames_with_depth'] += 1
        if self._ba is not None:
            self._ba.fold_in(track)
            if to_ba:
                self._ba_last_ns = frame.timestamp_ns
                self._ba.offer(keyframe_input(frame.index, frame.timestamp_ns,
                                              frame.source_image, depth,
                                              track.scaled(frame.index), record.intrinsics,
                                              record.hands, track.scale,
                                              self._lens.calibrated(frame)))
        with self._stage(STAGE_TRACK):
            best = track.best(frame.index)
        with self._stage(STAGE_PLACEMENT):
            fields = self._placement.fields(record.hands, best)
        result = FrameResult(timestamp_ns=frame.timestamp_ns, frame_index=frame.index,
                             intrinsics=record.intrinsics, is_keyframe=frame.keyframe,
                             depth=depth, hand_source=self._hand_source.name, **fields)
        with self._stage(STAGE_OUTPUT):
            return self._output.apply(result)

    def _scale_samples(self, record: CameraSpaceFrame, depth_kept: bool
                       ) -> tuple[np.ndarray, np.ndarray]:
        """Return the metric-scale samples of a frame's hands (and their unit model depths).

        On the frames that are sampled: every frame while the scale warms up; after that
        every ``sample_interval``-th frame and any frame whose depth is computed anyway (a
        tracker reference, or ``depth_kept``: a keyframe for BA or ``depth_maps``).
        """
        depth, hands = record.depth, record.hands
        interval = self.config.metric_scale.sample_interval
        if depth is None or not hands or not (
                depth.computed or depth_kept or self.pose_track.scale_state == 'warmup'
                or record.frame.index % interval == 0):
            return np.zeros(0), np.zeros(0)
        samples = depth_ratios(depth.model(), record.frame, hands) * self._scale_correction
        return samples, np.ones(len(samples))

    def _checkpoint_name(self) -> str:
        """Return what the weights came from, for error messages."""
        checkpoint = self.config.model.checkpoint
        return (f'checkpoint {checkpoint}' if checkpoint is not None
                else f'seeded untrained weights (seed {self.config.model.seed})')


def _scale_correction(config: EngineConfig) -> float:
    """Return the hand-depth correction of the metric scale: configured, or the checkpoint's."""
    configured = config.metric_scale.hand_depth_correction
    if configured is not None:
        return configured
    checkpoint = config.model.checkpoint
    return 1.0 if checkpoint is None else hand_depth_correction(resolve_checkpoint(checkpoint))


@contextlib.contextmanager
def _timed(timer: Callable[[str, float], None], name: str) -> Iterator[None]:
    """Tell ``timer`` the seconds the body took, as ``name`` (also when it raises)."""
    start = time.perf_counter()
    try:
        yield
    finally:
        timer(name, time.perf_counter() - start)


def _done(records: list[CameraSpaceFrame]) -> Future:
    """Return a finished future holding ``records`` (results queue in push order)."""
    future: Future = Future()
    future.set_result(records)
    return future
