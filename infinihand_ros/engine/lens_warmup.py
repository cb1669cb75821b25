"""A fixed camera's lens, estimated beside the stream instead of in front of it.

A fixed camera whose hands come from outside the model needs the model only for its lens. With
``lens_warmup: beside`` (live) its first frames go out at once with a provisional lens (flagged
``provisional_intrinsics`` in their results): the median of the predictions made so far, or before
the first one a nominal field of view (``NOMINAL_HFOV_DEG``). Meanwhile a worker thread predicts
the intrinsics of one frame at a time (the newest offered while it was busy), each on its own and
at most a third of the time, until ``wanted`` predictions are in; their median is then the stream's
lens (``settled``). With ``first`` (offline: results that do not depend on timing) the first
``wanted`` frames are predicted in the caller's thread instead, each given the median so far.
"""

from collections.abc import Callable
from concurrent.futures import Future
from concurrent.futures import ThreadPoolExecutor
import math
import threading
import time
from typing import Final

from infinihand_ros.core.datatypes import Intrinsics
import numpy as np

#: The horizontal field of view of the lens given before the first prediction (a webcam's).
NOMINAL_HFOV_DEG: Final = 60.0
#: Beside the stream the worker predicts at most this share of the time (it rests twice as
#: long as a prediction took), so the hand source keeps the machine's cores for the stream.
BUSY_SHARE: Final = 1.0 / 3.0


def nominal_intrinsics(width: int, height: int) -> Intrinsics:
    """Return a pinhole lens of ``NOMINAL_HFOV_DEG`` for an image of this size."""
    focal = 0.5 * width / math.tan(math.radians(NOMINAL_HFOV_DEG) / 2.0)
    return Intrinsics(focal, focal, (width - 1) / 2.0, (height - 1) / 2.0, width, height)


class LensWarmup:
    """Predictions of a fixed camera's intrinsics on a worker thread, and their median."""

    def __init__(self, predict: Callable[[np.ndarray], Intrinsics], wanted: int,
                 beside: bool) -> None:
        """Predict nothing yet.

        Args:
            predict: returns the model's intrinsics of one RGB image, in its pixels.
            wanted: predictions whose median settles the lens (``lens_frames``).
            beside: predict in a worker thread (``lens_warmup: beside``), else in the caller's.

        """
        self._predict = predict
        self._wanted = wanted
        self._beside = beside
        self._lock = threading.Lock()
        self._predicted: list[Intrinsics] = []
        self._running: Future | None = None
        self._worker: ThreadPoolExecutor | None = None
        self.settled: Intrinsics | None = None
        self.offered = False  # a frame without intrinsics came (the estimation started)

    def lens(self, image: np.ndarray) -> tuple[Intrinsics, bool]:
        """Offer a frame for prediction; return the lens for it and whether it is provisional.

        The frame is predicted in the worker thread if that is idle and the lens is not settled.
        """
        self.offered = True
        if not self._beside:
            if self.settled is None:
                self._run(image)
            if self.settled is not None:
                return self.settled, False
            return _median(self._predicted), True
        with self._lock:
            if self.settled is not None:
                return self.settled, False
            if self._running is None or self._running.done():
                if self._worker is None:
                    self._worker = ThreadPoolExecutor(max_workers=1,
                                                      thread_name_prefix='lens_warmup')
                self._running = self._worker.submit(self._run, image.copy())
            height, width = image.shape[:2]
            if not self._predicted:
                return nominal_intrinsics(width, height), True
            return _median(self._predicted), True

    def reset(self) -> None:
        """Start a new stream: no prediction kept (one still running is dropped)."""
        self.drain()
        with self._lock:
            self._predicted = []
            self.settled = None
            self.offered = False

    def drain(self) -> None:
        """Wait for a prediction still running (its result is kept)."""
        running = self._running
        if running is not None:
            running.exception()

    def close(self) -> None:
        """Stop the worker thread."""
        if self._worker is not None:
            self._worker.shutdown(wait=True)

    def _run(self, image: np.ndarray) -> None:
        """Predict one frame's intrinsics; settle once enough came (then rest, beside)."""
        start = time.perf_counter()
        intrinsics = self._predict(image)
        with self._lock:
            if self.settled is not None:
                return
            self._predicted.append(intrinsics)
            if len(self._predicted) >= self._wanted:
                self.settled = _median(self._predicted)
                return
        if self._beside:
            time.sleep((time.perf_counter() - start) * (1.0 / BUSY_SHARE - 1.0))


def _median(predicted: list[Intrinsics]) -> Intrinsics:
    """Return the per-parameter median lens of ``predicted`` (one image size)."""
    values = np.median([[k.fx, k.fy, k.cx, k.cy] for k in predicted], axis=0)
    return Intrinsics(*values, predicted[0].width, predicted[0].height)
