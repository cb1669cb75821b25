"""The one streaming engine: push frames, get per-frame camera poses and world-space hands.

Each push is prepare, route, run, finish (``docs/architecture.md`` walks through it). The stamp
goes through the stream policy (``stream_policy.py``), the frame is checked and fitted to the
model (``frame_input.py``), the schedule picks its route (``schedule.py``; how often a moving
camera's geometry branch runs: ``pacing.py``, and a frame can go out before its geometry branch
runs: ``deferred_geometry.py``), the paper's camera-space pass runs it in blocks
(``camera_space_pass.py``: the anchors together, then per frame or per window), and frame by
frame, in order, each record goes to the pose track (the per-frame tracker, the metric scale, BA
corrections), to the BA backend (``ba_backend.py``), has its hands placed in the world once
(``world_placement.py``) and passes the output stage (``output/``). The depth head runs only
where a depth is used. A fixed camera with hands from outside the model runs no geometry
branch once its lens is known (``stream_lens.py``, ``lens_warmup.py``). A hand source that
reads images (MediaPipe) does so in its own thread, in push order (``hands/reader.py``); for a
fixed camera a live caller can start it when the image arrives (``detect_ahead``).

Threading contract: one caller at a time. ``push``, ``flush``, ``reset``, ``catch_up`` and
``close`` raise ``EngineStateError`` when called while another thread is inside one of them, and
after ``close()``; nothing is consumed then. ``detect_ahead``, ``stamp_step`` and
``observe_input`` alone may be called from another thread (an image callback) while they run.
"""

from collections.abc import Iterator
from collections.abc import Sequence
import contextlib
import dataclasses
import threading
import time

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.errors import EngineStateError
from infinihand_ros.core.errors import InputError
from infinihand_ros.core.errors import ModelOutputError
from infinihand_ros.engine import stage_timing
from infinihand_ros.engine.ba_backend import BABackend
from infinihand_ros.engine.ba_backend import KeyframeFeed
from infinihand_ros.engine.ba_in_process import InProcessBA
from infinihand_ros.engine.camera_space import CameraSpaceFrame
from infinihand_ros.engine.camera_space import PreparedFrame
from infinihand_ros.engine.camera_space import with_hand_boxes
from infinihand_ros.engine.camera_space_pass import CameraSpacePass
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.deferred_geometry import DeferredGeometry
from infinihand_ros.engine.frame_input import check_image
from infinihand_ros.engine.frame_input import check_intrinsics
from infinihand_ros.engine.frame_input import LensRectifier
from infinihand_ros.engine.hands.reader import HandReader
from infinihand_ros.engine.hands.source import build_hand_source
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.model_builder import InfiniHandModel
from infinihand_ros.engine.output.stage import OutputStage
from infinihand_ros.engine.pacing import Pacer
from infinihand_ros.engine.pose_track import PoseTrack
from infinihand_ros.engine.scale_sampling import scale_correction
from infinihand_ros.engine.scale_sampling import scale_samples
from infinihand_ros.engine.schedule import FrameSituation
from infinihand_ros.engine.schedule import Route
from infinihand_ros.engine.schedule import route
from infinihand_ros.engine.stream_lens import StreamLens
from infinihand_ros.engine.stream_policy import StreamPolicy
from infinihand_ros.engine.timestamps import check_timestamp
from infinihand_ros.engine.timestamps import StampStep
from infinihand_ros.engine.world_placement import WorldPlacement
from infinihand_ros.model.geometry_stream import GeometryStream
import numpy as np


class StreamingEngine:
    """Frames in (RGB uint8, stamp, optional intrinsics), ``FrameResult``s out, in order.

    Attributes:
        stage_timer: None, or called with (stage name, seconds) after each timed stage
            (``engine/stage_timing.py``), from the thread that ran it; for profiling.

    """

    def __init__(self, config: EngineConfig | None = None,
                 model: InfiniHandModel | None = None,
                 ba_backend: BABackend | None = None) -> None:
        """Build the engine (and its model, unless one is given) from ``config``.

        Args:
            config: the engine settings (``build_engine_config``); None: the defaults, the
                ``live`` profile (real camera images).
            model: a built model to use instead of building one from ``config``.
            ba_backend: where keyframes go for bundle adjustment; None: an ``InProcessBA``
                when ``config.bundle_adjustment`` is set, else no BA. Not with
                ``camera_motion: static`` (a fixed camera needs no BA).

        Raises:
            ConfigError: for a BA backend with ``camera_motion: static``.

        """
        self.config = config or EngineConfig()
        self.static = self.config.camera_motion == 'static'
        self._tracking = self.config.tracker.enabled and not self.static  # images to track
        if ba_backend is not None and self.static:
            raise ConfigError('engine.camera_motion: static takes no bundle-adjustment backend '
                              '(a fixed camera is the world frame)')
        self.model = model or build_model(self.config)
        self.stage_timer: stage_timing.StageTimer | None = None
        self._scale_correction = scale_correction(self.config.metric_scale,
                                                  self.config.model.checkpoint)
        self._hand_source = build_hand_source(self.config.hands,
                                              self.model.hand_branch.hand_models)
        self._output = OutputStage(self.config.output, self.model.hand_branch.hand_models,
                                   relabel=not self._hand_source.decides_sides)
        if ba_backend is None and self.config.bundle_adjustment is not None and not self.static:
            ba_backend = InProcessBA(self.config.bundle_adjustment,
                                     self.config.pose_track.capacity)
        self._ba = ba_backend
        self._placement = WorldPlacement(self.static, raw_poses=ba_backend is not None)
        pool = (self.config.bundle_adjustment or BAConfig()).pool
        self._feed = None if ba_backend is None else KeyframeFeed(ba_backend, pool.min_interval_s)
        # The hand source reads each image in its own thread, beside the model (in order).
        self._reader = (HandReader(self._hand_source,
                                   lambda: self._stage(stage_timing.STAGE_DETECTION))
                        if self._hand_source.needs_image else None)
        self._policy = StreamPolicy(self.config.restart_after_s)
        self._lens = StreamLens(self.config.lens_frames, self.static,
                                self._hand_source.uses_hand_branch,
                                lambda image: self._pass.predict_intrinsics(image),
                                beside=self.config.lens_warmup == 'beside')
        self._pass = CameraSpacePass(self.model, self.config, self._hand_source, self._reader,
                                     self._lens, self._stage)
        # The geometry branch of a frame answered first (catch_up, or the next call).
        geometry = self.model.geometry
        self._pacer = Pacer(self.config.geometry_interval, self.config.geometry_lag,
                            self.config.pacing,
                            applies=(self.config.mode == 'per_frame' and self._tracking
                                     and not self._hand_source.uses_hand_branch))
        self._deferred = DeferredGeometry(
            self._pass.geometry_only,
            lambda: (*geometry.aggregator.frame_blocks, *geometry.aggregator.global_blocks,
                     geometry.depth_head), self._pacer.lag, self._pacer.geometry_cost)
        self._rectifier = LensRectifier()  # distorted frames -> pinhole ones with the same K
        self._guard = threading.Lock()
        self._closed = False
        self._start_sequence()

    def _start_sequence(self) -> None:
        """Reset every per-sequence state (memories, counters, track, BA)."""
        self._frames_pushed = 0
        self._policy.accept(None)
        self._accepted_stamp: int | None = None  # last stamp of a block the model accepted
        self._lens.reset()
        self._counts = {'frames_with_depth': 0, 'frames_without_geometry': 0,
                        'geometry_failures': 0}
        # (index, source intrinsics, model-input intrinsics) of the last geometry frame
        self._geometry_seen: tuple[int, Intrinsics, Intrinsics] | None = None
        self._deferred.reset()
        self._pacer.reset()
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
                'windows_in_flight': self._pass.windows_in_flight,
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
                'stream_restarts': self._policy.restarts,
                'pacing': self._pacer.state().as_dict(),
                'lens_provisional': self._lens.provisional}

    @property
    def model_stream(self) -> GeometryStream:
        """Return the model's streaming state (memories) of the current stream, to inspect."""
        return self._pass.stream

    @property
    def last_accepted_ns(self) -> int | None:
        """Return the stamp of the stream's last accepted frame, None before its first."""
        return self._policy.last_ns

    def stamp_step(self, timestamp_ns: int) -> StampStep:
        """Return how ``push`` takes a frame stamped ``timestamp_ns`` now; changes nothing.

        ``NEXT``: it continues the stream; ``OUT_OF_ORDER``: not after the last accepted frame,
        refused; ``RESTART``: more than ``restart_after_s`` before it, a new stream starts with
        it. Safe from any thread, for a caller that resets what it keeps per stream first.
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
                model's predicted field of view; a lens with distortion is rectified to the
                pinhole camera with the same K first (``frame_input.LensRectifier``).

        Raises:
            InputError: for a bad image, stamp or intrinsics, and for a stamp out of order
                (counted in ``statistics['frames_out_of_order']``); the stream is left
                unchanged.
            ModelOutputError: when the network's outputs are not finite (names the checkpoint;
                the frames of that block are not added to the stream).
            EngineStateError: after ``close()`` or when another thread is inside the engine.

        """
        with self._exclusive():
            start = time.perf_counter()
            image = self._rectifier.rectify(image, intrinsics)  # pinhole from here on
            frame = self._prepare(image, timestamp_ns, intrinsics)
            settling = time.perf_counter()
            self._settle_owed(frame)  # the owed geometry where due (the gate still open)
            settled = time.perf_counter() - settling  # geometry, timed where it runs
            with self._deferred.holding():
                self._deferred.lag = self._pacer.lag
                way = self._route(frame)
                self._run(way, frame, image)
                results = self._finish_ready(wait=False)
            if way in (Route.TRACKED, Route.TRACKED_FIRST):
                self._pacer.frame_cost(time.perf_counter() - start - settled)
            return results

    def observe_input(self, arrival_ns: int) -> None:
        """Note when an image arrived at a live caller (``time.monotonic_ns()``), pushed or not.

        From any thread. ``geometry_interval: auto`` paces the engine to the rate images arrive
        at; without these notes, to the stamps of the frames pushed (which drops spread out).
        """
        self._pacer.arrived(arrival_ns)

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
            image = self._rectifier.rectify_like_last(check_image(image))
        except InputError:
            return False  # push reports it
        return self._reader.read_ahead(image, timestamp_ns, self._frames_pushed,
                                       self._policy.last_ns)

    def catch_up(self) -> None:
        """Run or start the geometry branch a frame whose result went out first owes (if any).

        For a live caller, right after publishing a result: where the next frame would take its
        outputs in, it runs here (or is waited for); with ``geometry_lag`` >= 1 it starts in a
        worker thread, held while a frame is pushed. Without catch_up the call that needs it
        runs it. Results are the same either way.

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
            if self._pass.pending:
                self._run_block()
            return self._finish_ready(wait=True)

    def refined(self, results: Sequence[FrameResult],
                timeout_s: float | None = None) -> list[FrameResult]:
        """Return ``results`` on the final trajectory, for offline runs (after ``flush()``).

        Waits for the BA calls still queued (at most ``timeout_s``) and, with
        ``ba.episode.enabled``, refines the whole episode once, then gives every frame the pose
        the track holds now (all BA corrections, the final metric scale) with its hands and
        depth placed again, ``ba_failed`` where its last BA call failed and ``episode_refined``
        where it carries the accepted whole-episode refinement. Without BA only the scale
        changes. Frames older than the track's ``pose_track.capacity`` are returned unchanged.

        Raises:
            EngineStateError: after ``close()`` or when another thread is inside the engine.

        """
        with self._exclusive():
            self._pay_geometry()
            failed, episode = frozenset(), False
            if self._ba is not None:
                self._ba.settle(self.pose_track, timeout_s)
                failed, episode = self._ba.failed_frames(), self._ba.episode_refined()
            return [self._on_final_trajectory(result, failed, episode) for result in results]

    def _on_final_trajectory(self, result: FrameResult, ba_failed: frozenset[int],
                             episode_refined: bool) -> FrameResult:
        """Return ``result`` placed with the track's current (not live) pose and scale."""
        try:
            best = self.pose_track.best(result.frame_index, live=False)
        except KeyError:  # no longer in the track
            return result
        return self._placement.on_final_trajectory(
            result, best, result.frame_index in ba_failed, episode_refined)

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
            self._pass.close()
            if self._reader is not None:
                self._reader.close()
            self._deferred.close()
            self._lens.close()
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
        return stage_timing.timed(self.stage_timer, name)

    def _restart(self) -> None:
        """Start a new sequence (``reset``, from inside a call)."""
        self._drain()
        self._pass.reset()
        if self._ba is not None:
            self._ba.reset()
            self._feed.reset()
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
        with self._stage(stage_timing.STAGE_PREPARE):
            frame = self._pass.prepare(image, stamp, intrinsics, self._frames_pushed)
        self._frames_pushed += 1
        self._policy.accept(frame.timestamp_ns)
        self._pacer.pushed(frame.timestamp_ns)
        return frame

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
            geometry_interval=self._pacer.interval, tracking=self._tracking,
            hand_branch=self._hand_source.uses_hand_branch, held_back=bool(self._pass.pending),
            in_anchors=frame.index < self._pass.anchor_frames, frames_since_geometry=since,
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
            if self._pass.hold(frame):
                self._run_block()
            return
        self._accepted_stamp = frame.timestamp_ns
        if way is Route.STATIC:  # no model input: the geometry branch is not needed
            self._counts['frames_without_geometry'] += 1
            self._pass.queue_static(frame)
            return
        if way is Route.TRACKED:  # enters no streaming memory
            frame = dataclasses.replace(frame, keyframe=False)
            self._counts['frames_without_geometry'] += 1
        record = self._pass.queue_tracked(frame, self._geometry_seen)
        if way is Route.TRACKED_FIRST:
            self._deferred.owe(record)

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
        self.pose_track.observe_scale(*self._scale_samples_of(record, True))
        if record.depth.computed:
            self._counts['frames_with_depth'] += 1

    def _run_block(self) -> None:
        """Run the geometry branch on the held-back frames (their hands follow in the pass)."""
        count = len(self._pass.pending)
        start = time.perf_counter()
        try:
            frames = self._pass.run_block()
        except ModelOutputError as exc:  # the block's frames were not added: forget them
            self._frames_pushed -= count
            self._policy.accept(self._accepted_stamp)
            raise ModelOutputError(f'{self.config.model.weights_name}: {exc}') from exc
        self._accepted_stamp = frames[-1].timestamp_ns
        self._deferred.failed = False
        if count == 1:  # a frame's geometry branch (an anchor block's is no single frame's)
            self._pacer.geometry_cost(time.perf_counter() - start)

    def _finish_ready(self, wait: bool) -> list[FrameResult]:
        """Finish the records that are ready, in order; return their results (all: ``wait``)."""
        results: list[FrameResult] = []
        for record in self._pass.records(wait):
            with self._stage(stage_timing.STAGE_FINISH):
                results.append(self._finish(record))
        return results

    def _drain(self) -> None:
        """Wait for queued hand detection and decoding and drop their results (reset, close)."""
        self._pass.drain()
        self._deferred.drain()
        if self._reader is not None:
            self._reader.drain()

    def _finish(self, record: CameraSpaceFrame) -> FrameResult:
        """Track the frame's pose, feed BA, place its hands in the world: its final result."""
        frame = record.frame
        track = self.pose_track
        view = (None if record.view is None
                else with_hand_boxes(record.view, frame, record.hands))
        with self._stage(stage_timing.STAGE_TRACK):
            state = track.add(frame.index, frame.timestamp_ns, record.T_raw, view)
        self._deferred.finished(record, track.tracker.moment)
        if record.T_raw is not None and view is not None:
            self._geometry_seen = (frame.index, record.intrinsics, view.intrinsics)
        if frame.found().scene_cut or state == 'reinitialised':
            self._output.new_scene()
        to_ba = self._feed is not None and self._feed.wants(frame, record.depth is not None)
        kept = record.depth is not None and frame.keyframe and (to_ba or self.config.depth_maps)
        with self._stage(stage_timing.STAGE_TRACK):
            track.observe_scale(*self._scale_samples_of(record, kept))
        depth = (frame.mapping.map_to_source(record.depth.model()) * track.scale if kept
                 else None)
        if record.depth is not None and record.depth.computed:
            self._counts['frames_with_depth'] += 1
        if self._ba is not None:
            self._ba.fold_in(track)
            if to_ba:
                self._feed.offer(record, depth, track, self._lens.calibrated(frame))
        with self._stage(stage_timing.STAGE_TRACK):
            best = track.best(frame.index)
        with self._stage(stage_timing.STAGE_PLACEMENT):
            fields = self._placement.fields(record.hands, best)
        result = FrameResult(timestamp_ns=frame.timestamp_ns, frame_index=frame.index,
                             intrinsics=record.intrinsics, is_keyframe=frame.keyframe,
                             depth=depth, hand_source=self._hand_source.name,
                             provisional_intrinsics=frame.provisional_lens, **fields)
        with self._stage(stage_timing.STAGE_OUTPUT):
            return self._output.apply(result)

    def _scale_samples_of(self, record: CameraSpaceFrame, depth_kept: bool
                          ) -> tuple[np.ndarray, np.ndarray]:
        """Return the metric-scale samples of a frame's hands (``scale_samples``)."""
        return scale_samples(record, depth_kept, self.pose_track.scale_state == 'warmup',
                             self.config.metric_scale.sample_interval, self._scale_correction)
