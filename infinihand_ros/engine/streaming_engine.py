"""The one streaming engine: push frames, get per-frame camera poses and world-space hands.

The first ``anchor_frames`` frames are held back and processed together (the paper's anchor
context), in both modes. After that, per-frame mode runs each frame as it arrives; windowed mode
collects ``window`` frames, runs the backbone on them in one call and hands the decoding (hand
branch, scale, world frame) to a worker thread, so the backbone of the next window overlaps the
decoding of this one (paper Sec. 4.4). Attention inside a window is causal, so both modes give
the same per-frame results. Memory is bounded: the streaming memory is capped (see
``model/streaming_memory.py``) and at most one window waits here.
"""

from collections import deque
from concurrent.futures import Future
from concurrent.futures import ThreadPoolExecutor

from infinihand_ros.ba.config import load_ba_config
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.engine.ba_stage import BundleAdjustmentStage
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.engine.config import load_engine_config
from infinihand_ros.engine.decode import decode_block
from infinihand_ros.engine.decode import DecodeSettings
from infinihand_ros.engine.decode import PreparedFrame
from infinihand_ros.engine.frame_input import check_image
from infinihand_ros.engine.frame_input import check_intrinsics
from infinihand_ros.engine.frame_input import letterbox
from infinihand_ros.engine.metric_scale import MetricScaleEstimator
from infinihand_ros.engine.metric_scale import ScaleEstimate
from infinihand_ros.engine.model_builder import build_model
from infinihand_ros.engine.model_builder import InfiniHandModel
from infinihand_ros.model.geometry_stream import GeometryStream
import numpy as np
import torch


class StreamingEngine:
    """Frames in (RGB uint8, stamp, optional intrinsics), ``FrameResult``s out, in order."""

    def __init__(self, config: EngineConfig | None = None,
                 model: InfiniHandModel | None = None) -> None:
        """Build the engine (and its model, unless one is given) from ``config``."""
        self.config = config or load_engine_config()
        self.model = model or build_model(self.config)
        geometry_config = self.model.geometry.config
        self._model_size = (geometry_config.aggregator.image_width,
                            geometry_config.aggregator.image_height)
        self._anchor_frames = geometry_config.memory.anchor_frames
        masks = geometry_config.masks
        self._settings = DecodeSettings(
            masks.threshold, masks.min_pixels, self.config.presence_threshold,
            (float(np.radians(self.config.fov_range_deg[0])),
             float(np.radians(self.config.fov_range_deg[1]))))
        self._device = next(self.model.parameters()).device
        self._stream = GeometryStream(self.model.geometry)
        self._scale = MetricScaleEstimator(self.config.metric_scale)
        self._decoder = (ThreadPoolExecutor(max_workers=1, thread_name_prefix='decode')
                         if self.config.mode == 'windowed' else None)
        self._pending: list[PreparedFrame] = []
        self._decoding: deque[Future] = deque()
        self._frames_pushed = 0
        self._ba = self._new_ba_stage()
        self._source_images: dict[int, np.ndarray] = {}  # keyframes in flight, for BA only

    def _new_ba_stage(self) -> BundleAdjustmentStage | None:
        """Return a fresh BA stage when bundle adjustment is on."""
        if not self.config.bundle_adjustment:
            return None
        return BundleAdjustmentStage(load_ba_config(self.config.ba_config))

    @property
    def ba_statistics(self) -> dict[str, int]:
        """Return BA selections submitted, calls done, selections dropped and calls failed."""
        if self._ba is None:
            return {'submitted': 0, 'done': 0, 'dropped': 0, 'failed': 0}
        return {'submitted': self._ba.calls_submitted, 'done': self._ba.calls_done,
                'dropped': self._ba.worker.dropped, 'failed': self._ba.worker.failures}

    @property
    def metric_scale(self) -> ScaleEstimate:
        """Return the current metric-scale estimate (metres per model unit)."""
        return self._scale.estimate()

    def push(self, image: np.ndarray, timestamp_ns: int,
             intrinsics: Intrinsics | None = None) -> list[FrameResult]:
        """Add one frame; return the results that are ready (possibly none, possibly several).

        Args:
            image: (H, W, 3) uint8 RGB.
            timestamp_ns: the image's stamp; it is copied to its result.
            intrinsics: the camera's intrinsics for this image size, or None to use the
                model's predicted field of view.

        Raises:
            InputError: for a bad image or intrinsics; the stream's state is left unchanged.

        """
        frame = self._prepare(image, int(timestamp_ns), intrinsics)
        if self._ba is not None and frame.keyframe:  # a copy: callers may reuse the buffer
            self._source_images[frame.index] = image.copy()
        self._pending.append(frame)
        self._frames_pushed += 1
        if len(self._pending) >= self._block_size():
            self._run_block()
        return self._collect(wait=False)

    def flush(self) -> list[FrameResult]:
        """Process every frame still held back and return all remaining results."""
        if self._pending:
            self._run_block()
        return self._collect(wait=True)

    def reset(self) -> None:
        """Start a new sequence: drop held-back frames, memories, the scale and the counters."""
        self._collect(wait=True)
        self._pending.clear()
        self._source_images.clear()
        self._stream.reset()
        self._scale.reset()
        self._frames_pushed = 0
        if self._ba is not None:
            self._ba.close()
            self._ba = self._new_ba_stage()

    def close(self) -> None:
        """Stop the decoding worker (windowed mode) and the BA worker."""
        if self._decoder is not None:
            self._decoder.shutdown(wait=True)
        if self._ba is not None:
            self._ba.close()

    def __enter__(self) -> 'StreamingEngine':
        """Return the engine."""
        return self

    def __exit__(self, *exc_info: object) -> None:
        """Stop the worker."""
        self.close()

    def _prepare(self, image: np.ndarray, timestamp_ns: int,
                 intrinsics: Intrinsics | None) -> PreparedFrame:
        """Check a frame and fit it to the model size (raises before any state changes)."""
        image = check_image(image)
        intrinsics = check_intrinsics(intrinsics, image)
        fitted, mapping = letterbox(image, self._model_size)
        pixels = torch.from_numpy(fitted).to(self._device).permute(2, 0, 1).float() / 255.0
        index = self._frames_pushed
        after_anchors = index - self._anchor_frames
        keyframe = after_anchors < 0 or after_anchors % self.config.keyframe_interval == 0
        return PreparedFrame(index, timestamp_ns, pixels, mapping, intrinsics, keyframe)

    def _block_size(self) -> int:
        """Return how many frames the next block needs."""
        first_pending = self._frames_pushed - len(self._pending)
        if first_pending < self._anchor_frames:
            return self._anchor_frames - first_pending
        return self.config.window if self.config.mode == 'windowed' else 1

    def _run_block(self) -> None:
        """Run the backbone on the held-back frames and queue (or do) their decoding."""
        frames, self._pending = self._pending, []
        images = torch.stack([frame.pixels for frame in frames])[None]
        with torch.inference_mode():
            output = self._stream.step(images, [frame.keyframe for frame in frames])
        arguments = (output, frames, self.model.hand_branch, self._scale, self._settings)
        if self._decoder is None:
            future: Future = Future()
            future.set_result(decode_block(*arguments))
        else:
            future = self._decoder.submit(decode_block, *arguments)
        self._decoding.append(future)

    def _collect(self, wait: bool) -> list[FrameResult]:
        """Return decoded results in order; wait for all of them when ``wait``."""
        results: list[FrameResult] = []
        while self._decoding and (wait or self._decoding[0].done()):
            results.extend(self._decoding.popleft().result())
        if self._ba is not None:
            results = [self._ba.apply(result, self._source_images.pop(result.frame_index, None))
                       for result in results]
        return results
