"""The paper's camera-space pass over a stream: frames in blocks through the model, records out.

The first ``anchor_frames`` frames are held back and run together (the paper's anchor context),
in both modes. After that, per-frame mode runs each frame as it arrives; windowed mode collects
``window`` frames, runs the geometry branch on them in one call and the hand branch in a worker
thread, so the geometry of the next window overlaps the hands of this one (paper Sec. 4.4). At
most one window is in the worker: the next one waits for it (bounded memory). Attention inside a
window is causal, so both modes give the same per-frame results. Frames that skip the geometry
branch (tracked from the image alone, or a fixed camera's without the model) get their records
here too, and every record waits in one queue, in push order, for the engine to finish it.
"""

from collections import deque
from collections.abc import Callable
from collections.abc import Iterator
from concurrent.futures import Future
from concurrent.futures import ThreadPoolExecutor
import contextlib
import dataclasses

from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.engine.camera_space import CameraSpaceFrame
from infinihand_ros.engine.camera_space import PreparedFrame
from infinihand_ros.engine.camera_space import split_frames
from infinihand_ros.engine.camera_space import split_geometry
from infinihand_ros.engine.camera_space import tracking_view
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.frame_input import check_image
from infinihand_ros.engine.frame_input import check_intrinsics
from infinihand_ros.engine.frame_input import fit_image
from infinihand_ros.engine.frame_input import FrameMapping
from infinihand_ros.engine.hands.reader import HandReader
from infinihand_ros.engine.hands.source import HandSource
from infinihand_ros.engine.model_builder import InfiniHandModel
from infinihand_ros.engine.stage_timing import STAGE_HANDS
from infinihand_ros.engine.stage_timing import STAGE_LIFT
from infinihand_ros.engine.stage_timing import STAGE_SPLIT
from infinihand_ros.engine.stream_lens import given_intrinsics
from infinihand_ros.engine.stream_lens import StreamLens
from infinihand_ros.model.geometry_model import cpu_bf16_supported
from infinihand_ros.model.geometry_model import GeometryOutput
from infinihand_ros.model.geometry_stream import GeometryStream
from infinihand_ros.model.infinihand_model import CameraSpaceOutput
import numpy as np
import torch


class CameraSpacePass:
    """The model's part of the engine: held-back blocks, the streaming memory, the record queue."""

    def __init__(self, model: InfiniHandModel, config: EngineConfig, source: HandSource,
                 reader: HandReader | None, lens: StreamLens,
                 stage: Callable[[str], contextlib.AbstractContextManager[None]]) -> None:
        """Set up the pass for ``model`` (a new stream).

        Args:
            model: the built model.
            config: the engine config (mode, window, keyframes, camera, detection, precision).
            source: the hand source (lifts the hands of each record).
            reader: reads each image's hands in its own thread (None: the source reads none).
            lens: the stream's lens, held after the first block where one is held.
            stage: returns a context that times its body as a named stage.

        """
        self.model = model
        self._source = source
        self._reader = reader
        self._static = config.camera_motion == 'static'
        self._tracking = config.tracker.enabled and not self._static  # images to track
        self._keyframe_interval = config.keyframe_interval
        self._lens = lens
        self._stage = stage
        self._window = config.window if config.mode == 'windowed' else 1
        self.anchor_frames = model.geometry.config.memory.anchor_frames
        detection = config.detection
        self._detection = model.hand_detection(detection.presence_threshold,
                                               detection.fov_range_deg, detection.peak_region,
                                               detection.region_join_px)
        self._device = next(model.parameters()).device
        self._cpu_bf16 = (config.cpu_precision == 'auto' and self._device.type == 'cpu'
                          and cpu_bf16_supported())
        self._decoder = (ThreadPoolExecutor(max_workers=1, thread_name_prefix='hand_decode')
                         if config.mode == 'windowed' else None)
        self.reset()

    def reset(self) -> None:
        """Start a new stream: a fresh streaming memory, nothing held back or queued."""
        self.stream: GeometryStream = self.model.new_stream()
        self.pending: list[PreparedFrame] = []  # held back for the next block
        self._decoding: deque[Future] = deque()  # records per block, in push order
        self._source_size: tuple[int, int] | None = None  # (width, height) of the stream

    @property
    def windows_in_flight(self) -> int:
        """Return how many blocks' hands are still being found."""
        return sum(not future.done() for future in self._decoding)

    def prepare(self, image: np.ndarray, timestamp_ns: int, intrinsics: Intrinsics | None,
                index: int) -> PreparedFrame:
        """Check a frame and fit it to the model size (raises before any state changes).

        A frame that goes on without the geometry branch (``_skips_geometry``) is not fitted:
        its ``pixels`` and ``mapping`` are None. Its hands are being read from here on.

        Args:
            image: (H, W, 3) uint8 RGB, the stream's size.
            timestamp_ns: its stamp (checked by the engine's stream policy).
            intrinsics: given source intrinsics, or None (the lens held, else predicted).
            index: the frame's index in the stream.

        Raises:
            InputError: for a bad image or intrinsics, or another size than the stream's.

        """
        image = check_image(image)
        intrinsics = check_intrinsics(intrinsics, image) or self._lens.fixed
        provisional = False
        if intrinsics is None and not self.pending:
            estimated = self._lens.static_lens(image)  # a fixed camera's, beside the stream
            if estimated is not None:
                intrinsics, provisional = estimated
        size = (image.shape[1], image.shape[0])
        if self._source_size not in (None, size):
            raise InputError(f"image: {size[0]}x{size[1]} px, but this stream's frames are "
                             f'{self._source_size[0]}x{self._source_size[1]} px; keep one image '
                             'size per stream (resize the frames) or reset() between streams')
        pixels = mapping = None
        if not self._skips_geometry(intrinsics):
            pixels, mapping = self._fit(image)
        self._source_size = size
        after_anchors = index - self.anchor_frames
        keyframe = after_anchors < 0 or after_anchors % self._keyframe_interval == 0
        detections = (None if self._reader is None
                      else self._reader.read(image, timestamp_ns, index))
        return PreparedFrame(index, timestamp_ns, pixels, mapping, intrinsics, keyframe, None,
                             detections, provisional)

    def _skips_geometry(self, intrinsics: Intrinsics | None) -> bool:
        """Return whether a frame with these given intrinsics goes on without the model.

        A fixed camera whose hands come from outside the model needs the geometry branch only
        for intrinsics: not when they are given, or once the first frames' predictions fixed
        them (``lens_frames``). Frames never overtake held-back ones.
        """
        return (self._static and not self._source.uses_hand_branch and not self.pending
                and intrinsics is not None)

    def _fit(self, image: np.ndarray) -> tuple[torch.Tensor, FrameMapping]:
        """Return a checked RGB image fitted to the model: (3, H, W) float32 in [0, 1], mapping."""
        geometry = self.model.geometry.config
        fitted, mapping = fit_image(image, geometry.preprocessing, geometry.aggregator)
        return (torch.from_numpy(fitted).to(self._device).permute(2, 0, 1).float() / 255.0,
                mapping)

    def hold(self, frame: PreparedFrame) -> bool:
        """Hold a frame back for the geometry branch; return whether its block is complete."""
        self.pending.append(frame)
        first = self.pending[0].index
        size = (self.anchor_frames - first if first < self.anchor_frames else self._window)
        return len(self.pending) >= size

    def run_block(self) -> list[PreparedFrame]:
        """Run the geometry branch on the held-back frames, queue (or do) their hands.

        Returns:
            the block's frames (now in the streaming memory).

        Raises:
            ModelOutputError: for non-finite outputs; the block's frames were not added to the
                memory and are dropped.

        """
        frames, self.pending = self.pending, []
        images = torch.stack([frame.pixels for frame in frames])[None]
        intrinsics, known = given_intrinsics(frames)
        with torch.inference_mode():
            geometry, poses, used = self.model.run_geometry(
                images, self.stream, [frame.keyframe for frame in frames], intrinsics,
                known, self._detection, self._cpu_bf16,
                masks=self._source.uses_hand_branch, depth=False)
        used = self._lens.hold(frames, used)
        if self._decoder is None:
            future: Future = _done(self._hands(images, geometry, poses, used, frames))
        else:
            for in_flight in self._decoding:  # back-pressure: one window in the worker
                in_flight.exception()  # waits; its results are collected by ``records``
            future = self._decoder.submit(self._hands, images, geometry, poses, used, frames)
        self._decoding.append(future)
        return frames

    def predict_intrinsics(self, image: np.ndarray) -> Intrinsics:
        """Return the model's intrinsics of one image on its own (a fresh stream), its pixels."""
        pixels, mapping = self._fit(image)
        with torch.inference_mode():
            _, _, used = self.model.run_geometry(
                pixels[None, None], self.model.new_stream(), [True], None, None,
                self._detection, self._cpu_bf16, masks=False, depth=False)
        height, width = pixels.shape[-2:]
        return mapping.intrinsics_to_source(
            Intrinsics.from_matrix(used[0, 0].double().cpu().numpy(), width, height))

    def geometry_only(self, frame: PreparedFrame) -> CameraSpaceFrame:
        """Run the geometry branch alone on a frame answered first; return its record.

        Raises:
            ModelOutputError: for non-finite outputs (the memory is left as it was).

        """
        intrinsics, known = given_intrinsics([frame])
        with torch.inference_mode():
            geometry, poses, used = self.model.run_geometry(
                frame.pixels[None, None], self.stream, [frame.keyframe], intrinsics, known,
                self._detection, self._cpu_bf16, masks=False, depth=False)
        return split_geometry(geometry, poses, used, [frame], self.model.geometry)[0]

    def queue_tracked(self, frame: PreparedFrame,
                      seen: tuple[int, Intrinsics, Intrinsics]) -> CameraSpaceFrame:
        """Queue (and return) a moving camera's record without the geometry branch.

        It has no network pose; its intrinsics are the frame's given ones, else those of the
        last geometry frame (``seen``: its index, source and model-input intrinsics).
        """
        _, intrinsics, model_intrinsics = seen
        if frame.intrinsics is not None:
            intrinsics = frame.intrinsics
            model_intrinsics = frame.mapping.intrinsics_to_model(frame.intrinsics)
        size = tuple(frame.pixels.shape[-2:])
        view = tracking_view(frame, None, model_intrinsics.matrix(), size)
        with self._stage(STAGE_LIFT):
            hands = self._source.camera_hands(frame.found(), (), intrinsics)
        record = CameraSpaceFrame(frame, None, intrinsics, hands, None, view)
        self._decoding.append(_done([record]))
        return record

    def queue_static(self, frame: PreparedFrame) -> None:
        """Queue a fixed camera's record with its source's hands, no model run."""
        with self._stage(STAGE_LIFT):
            hands = self._source.camera_hands(frame.found(), (), frame.intrinsics)
        self._decoding.append(_done([CameraSpaceFrame(frame, np.eye(4), frame.intrinsics,
                                                      hands, None, None)]))

    def records(self, wait: bool) -> Iterator[CameraSpaceFrame]:
        """Yield the queued records that are ready, in push order; all of them when ``wait``."""
        while self._decoding and (wait or self._decoding[0].done()):
            yield from self._decoding.popleft().result()

    def drain(self) -> None:
        """Wait for the queued blocks and drop them and the held-back frames (reset, close)."""
        while self._decoding:
            self._decoding.popleft().exception()
        self.pending.clear()

    def close(self) -> None:
        """Stop the hand-branch worker (after ``drain``)."""
        if self._decoder is not None:
            self._decoder.shutdown(wait=True)

    def _hands(self, images: torch.Tensor, geometry: GeometryOutput, poses: torch.Tensor,
               used: torch.Tensor, frames: list[PreparedFrame]) -> list[CameraSpaceFrame]:
        """Find a block's hands with the hand source; split it into per-frame records."""
        with self._stage(STAGE_HANDS):
            branch = self.model.geometry
            with torch.inference_mode():
                if self._source.uses_hand_branch:
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
            return self._source.camera_hands(record.frame.found(), record.hands,
                                             record.intrinsics)


def _done(records: list[CameraSpaceFrame]) -> Future:
    """Return a finished future holding ``records`` (results queue in push order)."""
    future: Future = Future()
    future.set_result(records)
    return future
