"""The one streaming engine: push frames, get per-frame camera poses and world-space hands.

Data flows one way. Each frame is checked and fitted to the model (``frame_input``), then the
paper's camera-space pass (``InfiniHandModel``: geometry through the streaming memory, poses, boxes
from masks, hand branch) runs per block. Frame by frame, in order, the camera-space record then
goes to the pose track (its per-frame tracker measures the pose in the image, with the network's
pose as prior; metric scale from the hands; BA corrections), to the bundle-adjustment backend
(keyframes; ``engine/ba_backend.py``), its hands are placed in the world once, with the track's
best pose (the identity with ``camera_motion: static``), and the output stage (``engine/output/``:
identity, shared shape, smoothing) gives the result every consumer gets. The depth head runs only
on the frames whose depth is used (a new tracker reference, a metric-scale sample, a keyframe for
BA; every keyframe with ``depth_maps``). A fixed camera whose hands come from outside the model
(``camera_motion: static`` with MediaPipe) skips the geometry branch wherever the intrinsics are
known (given, or fixed from the first frames' predictions): the hand source is all such a frame
needs. A moving camera with such a hand source runs the geometry branch on every
``geometry_interval``-th frame in per-frame mode (and wherever the tracker needs depth: a new
reference, or first, with the network's pose as prior, where it lost the camera); every other frame
is tracked from the image alone, with the last intrinsics, and carries no depth. Without BA, a
frame due for the geometry branch while the tracker holds the camera is also tracked from the image
first and its result goes out at once; the geometry branch then runs on it in ``catch_up()`` (a
live caller's idle time after publishing) or at the start of the next call, and the pose track
takes its outputs before the next frame. With ``geometry_lag: n`` (n >= 1) they come n frames
later: the next n frames are tracked from the image too, and they are taken in before the frame
after those (or before a frame that needs them first: the tracker lost the camera, the metric scale
still warms up); ``catch_up()`` then starts the branch in a worker thread, paused whenever a frame
is being pushed, so the next frames' answers do not wait for it. Results do not depend on when it
runs. A hand source that reads images (MediaPipe) does so in its own thread, in push order, while
the model runs on the frame. For a fixed camera a live caller can start it earlier, when the image
arrives (``detect_ahead``): the hands of the next frame are then read while the last one is still
being finished and published.

The first ``anchor_frames`` frames are held back and processed together (the paper's anchor
context), in both modes. After that, per-frame mode runs each frame as it arrives; windowed mode
collects ``window`` frames, runs the geometry branch on them in one call and the hand branch in
a worker thread, so the geometry of the next window overlaps the hands of this one (paper Sec.
4.4). At most one window is in the worker: the next one waits for it (bounded memory). Attention
inside a window is causal, so both modes give the same per-frame results.

Threading contract: one caller at a time. ``push``, ``flush``, ``reset``, ``catch_up`` and
``close`` raise ``EngineStateError`` when called while another thread is inside one of them, and
after ``close()``; nothing is consumed then. ``detect_ahead`` alone may be called from another
thread (an image callback) while they run.
"""

from collections import deque
from collections.abc import Iterator
from collections.abc import Sequence
from concurrent.futures import Future
from concurrent.futures import ThreadPoolExecutor
import contextlib
import dataclasses
import threading

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
from infinihand_ros.engine.camera_tracker import TrackerMoment
from infinihand_ros.engine.camera_tracker import TrackingView
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.config import load_engine_config
from infinihand_ros.engine.frame_input import check_image
from infinihand_ros.engine.frame_input import check_intrinsics
from infinihand_ros.engine.frame_input import fit_image
from infinihand_ros.engine.frame_input import LensRectifier
from infinihand_ros.engine.hands.source import build_hand_source
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.model_builder import InfiniHandModel
from infinihand_ros.engine.output.stage import OutputStage
from infinihand_ros.engine.pose_track import PoseTrack
from infinihand_ros.engine.pose_track import TrackedPose
from infinihand_ros.engine.timestamps import check_timestamp
from infinihand_ros.engine.world_placement import place_in_world
from infinihand_ros.model.geometry_model import cpu_bf16_supported
from infinihand_ros.model.geometry_model import GeometryOutput
from infinihand_ros.model.infinihand_model import CameraSpaceOutput
from infinihand_ros.model.io.bundled import hand_depth_correction
from infinihand_ros.model.io.bundled import resolve_checkpoint
import numpy as np
import torch


@dataclasses.dataclass
class _Owed:
    """A frame whose result went out before its geometry branch ran.

    Attributes:
        record: its record without geometry (hands, tracking view).
        moment: the tracker right after the frame.
        run: its geometry branch in the worker thread (``catch_up``), None until started.

    """

    record: CameraSpaceFrame
    moment: TrackerMoment | None = None
    run: Future | None = None


class _Gate:
    """Holds the geometry worker at block boundaries while a frame is being pushed."""

    def __init__(self) -> None:
        """Start open, with no worker thread known."""
        self._condition = threading.Condition()
        self._callers = 0
        self.worker: int | None = None  # the worker thread's ident

    @contextlib.contextmanager
    def closed(self) -> Iterator[None]:
        """Hold the worker at its next boundary while inside."""
        with self._condition:
            self._callers += 1
        try:
            yield
        finally:
            with self._condition:
                self._callers -= 1
                self._condition.notify_all()

    def boundary(self, *unused: object) -> None:
        """Wait here, in the worker thread, until no caller is inside (a forward pre-hook)."""
        if threading.get_ident() != self.worker:
            return
        with self._condition:
            self._condition.wait_for(lambda: self._callers == 0)


class StreamingEngine:
    """Frames in (RGB uint8, stamp, optional intrinsics), ``FrameResult``s out, in order."""

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
        self._scale_correction = _scale_correction(self.config)
        self._output = OutputStage(self.config.output, self.model.hand_branch.hand_models)
        self._hand_source = build_hand_source(self.config.hands,
                                              self.model.hand_branch.hand_models)
        if ba_backend is None and self.config.bundle_adjustment is not None and not self.static:
            ba_backend = InProcessBA(self.config.bundle_adjustment,
                                     self.config.pose_track.capacity)
        self._ba = ba_backend
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
        self._detector = (ThreadPoolExecutor(max_workers=1, thread_name_prefix='hand_detect')
                          if self._hand_source.needs_image else None)
        # The geometry branch of a frame answered first, started by catch_up (created then).
        self._geometry_worker: ThreadPoolExecutor | None = None
        self._gate = _Gate()
        self._gate_hooks: list[torch.utils.hooks.RemovableHandle] = []
        # Detections started at the images' arrival (detect_ahead), by stamp.
        self._ahead: dict[int, Future] = {}
        self._ahead_lock = threading.Lock()
        self._rectifier = LensRectifier()  # distorted frames -> pinhole ones with the same K
        self._guard = threading.Lock()
        self._closed = False
        self._start_sequence()

    def _start_sequence(self) -> None:
        """Reset every per-sequence state (memories, counters, track, BA)."""
        self._stream = self.model.new_stream()
        self._pending: list[PreparedFrame] = []
        self._decoding: deque[Future] = deque()
        self._frames_pushed = 0
        self._last_stamp: int | None = None
        self._accepted_stamp: int | None = None  # last stamp of a block the model accepted
        self._source_size: tuple[int, int] | None = None  # (width, height) of the stream
        self._predicted: list[Intrinsics] = []  # the stream's first predicted intrinsics
        self._fixed_intrinsics: Intrinsics | None = None  # ... and their median, once known
        self._counts = {'frames_with_depth': 0, 'frames_without_geometry': 0,
                        'geometry_failures': 0}
        # (index, source intrinsics, model-input intrinsics) of the last geometry frame
        self._geometry_seen: tuple[int, Intrinsics, Intrinsics] | None = None
        self._owed: _Owed | None = None  # a frame out before its geometry branch ran
        self._owed_failed = False  # its geometry branch failed: first until one succeeds
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
                'hands': self._hand_source.statistics()}

    def push(self, image: np.ndarray, timestamp_ns: int,
             intrinsics: Intrinsics | None = None) -> list[FrameResult]:
        """Add one frame; return the results that are ready (possibly none, possibly several).

        Args:
            image: (H, W, 3) uint8 RGB (the same size for the whole stream).
            timestamp_ns: the image's stamp, integer nanoseconds, increasing; copied to its
                result.
            intrinsics: the camera's intrinsics for this image size, or None to use the
                model's predicted field of view; a lens with distortion is rectified to the
                pinhole camera with the same K first (``frame_input.LensRectifier``).

        Raises:
            InputError: for a bad image, stamp or intrinsics; the stream is left unchanged.
            ModelOutputError: when the network's outputs are not finite (names the checkpoint;
                the frames of that block are not added to the stream).
            EngineStateError: after ``close()`` or when another thread is inside the engine.

        """
        with self._exclusive():
            image = self._rectifier.rectify(image, intrinsics)  # pinhole from here on
            frame = self._prepare(image, timestamp_ns, intrinsics)
            self._frames_pushed += 1
            self._last_stamp = frame.timestamp_ns
            if self._owed_due(frame):
                self._pay_geometry()  # the gate still open: this may wait for the worker
            with self._gate.closed():
                route = self._route(frame)
                if route == 'geometry':
                    if self._ba is not None and frame.keyframe:  # BA reads the keyframe's image
                        frame = dataclasses.replace(frame, source_image=image.copy())
                    self._pending.append(frame)
                    if len(self._pending) >= self._block_size():
                        self._run_block()
                    return self._collect(wait=False)
                self._accepted_stamp = frame.timestamp_ns
                if route == 'static':  # no model input: the geometry branch is not needed
                    self._decoding.append(_done(self._without_geometry(frame)))
                else:
                    if route == 'tracked':  # enters no streaming memory
                        frame = dataclasses.replace(frame, keyframe=False)
                        self._counts['frames_without_geometry'] += 1
                    record = self._tracked_only(frame)
                    self._decoding.append(_done([record]))
                    if route == 'tracked_first':
                        self._owed = _Owed(record)
                return self._collect(wait=False)

    @property
    def detects_ahead(self) -> bool:
        """Return whether ``detect_ahead`` starts anything (a fixed camera, MediaPipe hands)."""
        return self.static and self._detector is not None

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
            image = self._rectifier.rectify_like_last(check_image(image))
        except InputError:
            return False  # push reports it
        with self._ahead_lock:
            last = self._last_stamp
            if (last is not None and timestamp_ns <= last) or any(
                    stamp >= timestamp_ns for stamp in self._ahead):
                return False
            try:
                self._ahead[timestamp_ns] = self._detector.submit(
                    self._hand_source.detect, image.copy(), self._frames_pushed)
            except RuntimeError:  # the worker shut down meanwhile (close)
                return False
        return True

    def _detection_of(self, image: np.ndarray, timestamp_ns: int, index: int) -> Future | None:
        """Return the frame's hand detection: started ahead for its stamp, else started now.

        Detections started ahead for older stamps (images never pushed) are dropped.
        """
        if self._detector is None:
            return None
        with self._ahead_lock:
            ahead = self._ahead.pop(timestamp_ns, None)
            for stamp in [stamp for stamp in self._ahead if stamp < timestamp_ns]:
                del self._ahead[stamp]
        if ahead is not None:
            return ahead
        return self._detector.submit(self._hand_source.detect, image.copy(), index)

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
            owed = self._owed
            if owed is None or owed.moment is None:
                return
            if self._owed_late(self._frames_pushed):
                self._pay_geometry()  # the next frame takes it in
                return
            if owed.run is not None:
                return
            if self._geometry_worker is None:
                self._geometry_worker = ThreadPoolExecutor(max_workers=1,
                                                           thread_name_prefix='geometry')
                geometry = self.model.geometry
                for module in (*geometry.aggregator.frame_blocks,
                               *geometry.aggregator.global_blocks, geometry.depth_head):
                    self._gate_hooks.append(module.register_forward_pre_hook(self._gate.boundary))
            owed.run = self._geometry_worker.submit(self._owed_geometry, owed, True)

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
            self._drain()
            if self._ba is not None:
                self._ba.reset()
                self._ba_last_ns = None
            if self._detector is None:
                self._hand_source.reset()
            else:  # in its thread: a detection started ahead meanwhile may be running there
                self._detector.submit(self._hand_source.reset).result()
            self._start_sequence()

    def close(self) -> None:
        """Stop the hand detection and decoding workers and the BA worker; idempotent."""
        with self._guard:
            if self._closed:
                return
            self._closed = True
            self._drain()
            for worker in (self._decoder, self._detector, self._geometry_worker):
                if worker is not None:
                    worker.shutdown(wait=True)
            for hook in self._gate_hooks:
                hook.remove()
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

    def _prepare(self, image: np.ndarray, timestamp_ns: int,
                 intrinsics: Intrinsics | None) -> PreparedFrame:
        """Check a frame and fit it to the model size (raises before any state changes).

        A frame that goes on without the geometry branch (``_skips_geometry``) is not fitted:
        its ``pixels`` and ``mapping`` are None.
        """
        stamp = check_timestamp(timestamp_ns, self._last_stamp)
        image = check_image(image)
        intrinsics = check_intrinsics(intrinsics, image) or self._fixed_intrinsics
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
        detections = self._detection_of(image, stamp, index)
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

    def _without_geometry(self, frame: PreparedFrame) -> list[CameraSpaceFrame]:
        """Return a fixed camera's frame record with its source's hands, no model run."""
        self._counts['frames_without_geometry'] += 1
        hands = self._hand_source.camera_hands(frame.found(), (), frame.intrinsics)
        return [CameraSpaceFrame(frame, np.eye(4), frame.intrinsics, hands, None, None)]

    def _route(self, frame: PreparedFrame) -> str:
        """Return how a checked frame goes on.

        'static': a fixed camera's frame without the model; 'geometry': the geometry branch
        first (the paper's path); 'tracked': tracked from the image alone, between geometry
        frames; 'tracked_first': tracked from the image alone, its geometry branch run after
        its result went out. The last two only in per-frame mode for a tracked moving camera
        whose hands come from outside the model (``geometry_interval`` > 1), after the
        anchors. A frame where the tracker needs depth runs the geometry branch too: first
        when the tracker lost the camera (its network pose is the prior), after its result
        for a new reference; so does a frame with hands while the metric scale warms up (its
        depth gives the samples); it always comes first with BA (its keyframes carry their
        depth). A frame after one whose geometry is still owed (``geometry_lag`` >= 1) is
        'tracked' (the owed one brings the depth it would need).
        """
        if frame.pixels is None:
            return 'static'
        seen = self._geometry_seen
        tracker = self.pose_track.tracker
        if (self.config.geometry_interval == 1 or self.config.mode != 'per_frame'
                or not self._tracking or self._hand_source.uses_hand_branch or self._pending
                or frame.index < self._anchor_frames or seen is None or self._owed_failed
                or (tracker.needs_depth and tracker.lost)):
            return 'geometry'
        owed = self._owed
        since = frame.index - (seen[0] if owed is None else owed.record.frame.index)
        if (since < self.config.geometry_interval and not (tracker.needs_depth and owed is None)
                and not (self.pose_track.scale_state == 'warmup' and frame.found().hands)):
            return 'tracked'
        return 'geometry' if self._ba is not None else 'tracked_first'

    def _tracked_only(self, frame: PreparedFrame) -> CameraSpaceFrame:
        """Return a moving camera's frame record without the geometry branch: no network pose."""
        _, intrinsics, model_intrinsics = self._geometry_seen
        if frame.intrinsics is not None:
            intrinsics = frame.intrinsics
            model_intrinsics = frame.mapping.intrinsics_to_model(frame.intrinsics)
        size = tuple(frame.pixels.shape[-2:])
        view = tracking_view(frame, None, model_intrinsics.matrix(), size)
        hands = self._hand_source.camera_hands(frame.found(), (), intrinsics)
        return CameraSpaceFrame(frame, None, intrinsics, hands, None, view)

    def _owed_due(self, frame: PreparedFrame) -> bool:
        """Return whether the owed geometry branch is taken in before ``frame``.

        Before the frame after it, or with ``geometry_lag: n`` before the (n + 1)-th, or the
        first when that frame needs it: the tracker lost the camera (the frame runs the
        geometry branch first), or the metric scale warms up and the frame has hands.
        """
        if self._owed is None:
            return False
        tracker = self.pose_track.tracker
        return (self._owed_late(frame.index) or (tracker.needs_depth and tracker.lost)
                or (self.pose_track.scale_state == 'warmup' and bool(frame.found().hands)))

    def _owed_late(self, index: int) -> bool:
        """Return whether frame ``index`` comes more than ``geometry_lag`` after the owed one."""
        return index - self._owed.record.frame.index > self.config.geometry_lag

    def _owed_geometry(self, owed: _Owed, in_worker: bool = False) -> CameraSpaceFrame:
        """Run the geometry branch on a frame answered first; return its record.

        In the caller's thread, or the worker's (``catch_up``; ``in_worker``), where the depth
        a new tracker reference or the hands' scale samples will read is computed too.
        """
        if in_worker:
            self._gate.worker = threading.get_ident()
        frame = owed.record.frame
        intrinsics, known = self._given_intrinsics([frame])
        with torch.inference_mode():
            geometry, poses, used = self.model.run_geometry(
                frame.pixels[None, None], self._stream, [frame.keyframe], intrinsics, known,
                self._detection, self._cpu_bf16, masks=False, depth=False)
        record = split_geometry(geometry, poses, used, [frame], self.model.geometry)[0]
        if in_worker and (owed.record.hands or owed.moment.needs_depth):
            record.depth.model()
        return record

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
        owed, self._owed = self._owed, None
        if owed is None:
            return
        frame = owed.record.frame
        try:
            record = self._owed_geometry(owed) if owed.run is None else owed.run.result()
        except ModelOutputError:
            self._counts['geometry_failures'] += 1
            self._owed_failed = True
            return
        record = dataclasses.replace(record, hands=owed.record.hands,
                                     view=_with_hand_boxes(record.view, frame, owed.record.hands))
        self.pose_track.absorb(frame.index, record.T_raw, record.view, owed.moment)
        self._geometry_seen = (frame.index, record.intrinsics, record.view.intrinsics)
        self.pose_track.observe_scale(*self._scale_samples(record, True))
        if record.depth.computed:
            self._counts['frames_with_depth'] += 1

    def _hold_lens(self, frames: list[PreparedFrame], used: torch.Tensor) -> torch.Tensor:
        """Return a moving camera's first block's intrinsics as one lens, held for the stream.

        Its frames' predictions (model size) are replaced by their median, which the frames
        after it are given: one lens, so a pose is never re-measured through another focal
        length (a still camera would seem to move). Unchanged with given intrinsics, a fixed
        camera (``_fix_intrinsics``), the paper's hand branch or ``lens_frames`` 0.
        """
        if (self._fixed_intrinsics is not None or self.static or self.config.lens_frames == 0
                or self._hand_source.uses_hand_branch
                or any(frame.intrinsics is not None for frame in frames)):
            return used
        median = np.median(used[0].double().cpu().numpy(), axis=0)
        height, width = frames[0].pixels.shape[-2:]
        self._fixed_intrinsics = frames[0].mapping.intrinsics_to_source(
            Intrinsics.from_matrix(median, width, height))
        return torch.as_tensor(median, dtype=used.dtype).expand_as(used[0])[None].clone()

    def _calibrated(self, frame: PreparedFrame) -> bool:
        """Return whether the frame's intrinsics were given (not the lens held from predictions).

        BA refines a lens only where none was given.
        """
        return frame.intrinsics is not None and frame.intrinsics is not self._fixed_intrinsics

    def _fix_intrinsics(self, record: CameraSpaceFrame) -> None:
        """Collect a fixed camera's predicted intrinsics; hold their median once enough came."""
        wanted = self.config.lens_frames
        if (record.frame.intrinsics is not None or self._fixed_intrinsics is not None
                or wanted == 0 or not self.static or self._hand_source.uses_hand_branch):
            return
        self._predicted.append(record.intrinsics)
        if len(self._predicted) == wanted:
            values = np.median([[k.fx, k.fy, k.cx, k.cy] for k in self._predicted], axis=0)
            self._fixed_intrinsics = Intrinsics(*values, record.intrinsics.width,
                                                record.intrinsics.height)

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
        intrinsics, known = self._given_intrinsics(frames)
        try:
            with torch.inference_mode():
                geometry, poses, used = self.model.run_geometry(
                    images, self._stream, [frame.keyframe for frame in frames], intrinsics,
                    known, self._detection, self._cpu_bf16,
                    masks=self._hand_source.uses_hand_branch, depth=False)
        except ModelOutputError as exc:  # the block's frames were not added: forget them
            self._frames_pushed -= len(frames)
            self._last_stamp = self._accepted_stamp
            raise ModelOutputError(f'{self._checkpoint_name()}: {exc}') from exc
        self._accepted_stamp = frames[-1].timestamp_ns
        self._owed_failed = False
        used = self._hold_lens(frames, used)
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
        source = self._hand_source
        branch = self.model.geometry
        with torch.inference_mode():
            if source.uses_hand_branch:
                output: CameraSpaceOutput = self.model.run_hands(images, geometry, poses, used,
                                                                 None, self._detection)
                records = split_frames(output, frames, branch, self._tracking)
            else:
                records = split_geometry(geometry, poses, used, frames, branch, self._tracking)
        return [dataclasses.replace(record, hands=source.camera_hands(
            record.frame.found(), record.hands, record.intrinsics)) for record in records]

    def _given_intrinsics(self, frames: list[PreparedFrame]
                          ) -> tuple[torch.Tensor | None, torch.Tensor | None]:
        """Return (1, S, 3, 3) model-size K of the frames with given intrinsics, and which."""
        known = [frame.intrinsics is not None for frame in frames]
        if not any(known):
            return None, None
        matrices = np.stack([frame.mapping.intrinsics_to_model(frame.intrinsics).matrix()
                             if frame.intrinsics is not None else np.eye(3) for frame in frames])
        return (torch.as_tensor(matrices, dtype=torch.float64)[None],
                torch.tensor(known)[None])

    def _collect(self, wait: bool) -> list[FrameResult]:
        """Return finished results in order; wait for all of them when ``wait``."""
        results: list[FrameResult] = []
        while self._decoding and (wait or self._decoding[0].done()):
            for record in self._decoding.popleft().result():
                results.append(self._finish(record))
        return results

    def _drain(self) -> None:
        """Wait for queued hand detection and decoding and drop their results (reset, close)."""
        while self._decoding:
            self._decoding.popleft().exception()
        self._pending.clear()
        if self._owed is not None and self._owed.run is not None:
            self._owed.run.exception()  # its worker runs on (no caller inside) and ends
        self._owed = None
        with self._ahead_lock:
            self._ahead.clear()
        if self._detector is not None:  # one worker, in order: this runs after the queued ones
            self._detector.submit(lambda: None).result()

    def _finish(self, record: CameraSpaceFrame) -> FrameResult:
        """Track the frame's pose, feed BA, place its hands in the world: its final result."""
        frame = record.frame
        track = self.pose_track
        view = (None if record.view is None
                else _with_hand_boxes(record.view, frame, record.hands))
        state = track.add(frame.index, frame.timestamp_ns, record.T_raw, view)
        if self._owed is not None and self._owed.record is record:
            self._owed.moment = track.tracker.moment()
        if record.T_raw is not None and view is not None:
            self._geometry_seen = (frame.index, record.intrinsics, view.intrinsics)
        if frame.found().scene_cut or state == 'reinitialised':
            self._output.new_scene()
        to_ba = (self._ba is not None and frame.keyframe and frame.source_image is not None
                 and record.depth is not None
                 and (self._ba_last_ns is None
                      or frame.timestamp_ns - self._ba_last_ns >= self._ba_interval_ns))
        kept = record.depth is not None and frame.keyframe and (to_ba or self.config.depth_maps)
        track.observe_scale(*self._scale_samples(record, kept))
        self._fix_intrinsics(record)
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
                                              self._calibrated(frame)))
        return self._output.apply(FrameResult(
            timestamp_ns=frame.timestamp_ns, frame_index=frame.index,
            intrinsics=record.intrinsics, is_keyframe=frame.keyframe, depth=depth,
            hand_source=self._hand_source.name,
            **self._posed(record.hands, track.best(frame.index))))

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

    def _on_final_trajectory(self, result: FrameResult,
                             ba_failed: frozenset[int]) -> FrameResult:
        """Return ``result`` with the track's current (not live) pose, scale and hands.

        The output stage's identity and shared shape are kept; its smoothing (of the live
        world-frame joints) is not, as the hands are placed again. The result is flagged
        ``ba_failed`` when its frame is in ``ba_failed`` (those whose last BA call failed).
        """
        try:
            best = self.pose_track.best(result.frame_index, live=False)
        except KeyError:  # no longer in the track
            return result
        depth = (None if result.depth is None
                 else result.depth * (best.scale / result.metric_scale))
        return dataclasses.replace(result, depth=depth,
                                   ba_failed=result.frame_index in ba_failed,
                                   **self._posed(result.hands, best))

    def _posed(self, hands: tuple[HandState, ...], best: TrackedPose) -> dict[str, object]:
        """Return the ``FrameResult`` fields that follow from a tracked pose (hands placed)."""
        pose = CameraPose.identity() if self.static else best.camera_pose
        return {'camera_pose': pose,
                'hands': place_in_world(hands, pose), 'metric_scale': best.scale,
                'raw_camera_pose': best.scaled_pose if self._ba is not None else None,
                'pose_version': best.version,
                'tracking': 'static' if self.static else best.tracking}

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


def _with_hand_boxes(view: TrackingView, frame: PreparedFrame,
                     hands: tuple[HandState, ...]) -> TrackingView:
    """Return ``view`` with the hands' boxes in model-input pixels (never tracked)."""
    boxes = [frame.mapping.points_to_model(hand.box_xyxy.reshape(2, 2)).reshape(4)
             for hand in hands]
    return dataclasses.replace(view, hand_boxes=np.array(boxes).reshape(-1, 4))


def _done(records: list[CameraSpaceFrame]) -> Future:
    """Return a finished future holding ``records`` (results queue in push order)."""
    future: Future = Future()
    future.set_result(records)
    return future
