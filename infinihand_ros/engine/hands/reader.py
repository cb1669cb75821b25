"""The hand source reading images in its own thread, in push order, beside the model.

A hand source that reads images (MediaPipe, or the hand branch's verifier) gets each pushed
image in one worker thread, so the detection runs while the model runs on the frame; the frame
holds the future (``PreparedFrame.detections``). For a fixed camera a live caller can start it
earlier, when the image arrives (``read_ahead``): the hands of the next frame are then read
while the last one is still being finished and published. A read started ahead that has not
begun when a newer image arrives is cancelled (that image is never pushed: the newer one replaces
it), so reads never queue up behind a camera faster than the source; one already running is
dropped at the next push.
"""

from collections.abc import Callable
from concurrent.futures import Future
from concurrent.futures import ThreadPoolExecutor
import contextlib
import threading

from infinihand_ros.engine.hands.detections import FrameDetections
from infinihand_ros.engine.hands.source import HandSource
import numpy as np


class HandReader:
    """Runs ``HandSource.detect`` in one worker thread, in order; holds reads started ahead."""

    def __init__(self, source: HandSource,
                 timed: Callable[[], contextlib.AbstractContextManager[None]]) -> None:
        """Start the worker thread.

        Args:
            source: the hand source (its ``needs_image`` is True).
            timed: returns a context that times one detection (in the worker thread).

        """
        self._source = source
        self._timed = timed
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix='hand_detect')
        self._ahead: dict[int, Future] = {}  # reads started at the images' arrival, by stamp
        self._lock = threading.Lock()

    def read_ahead(self, image: np.ndarray, timestamp_ns: int, index: int,
                   last_ns: int | None) -> bool:
        """Start reading an image that will be pushed next; return whether it started.

        Args:
            image: the checked RGB image (copied).
            timestamp_ns: its stamp; not started unless newer than ``last_ns`` (the last
                pushed frame's) and every image read ahead.
            index: the frame index it will have.
            last_ns: the stamp of the last pushed frame, None before the first.

        """
        with self._lock:
            if (last_ns is not None and timestamp_ns <= last_ns) or any(
                    stamp >= timestamp_ns for stamp in self._ahead):
                return False
            self._cancel_before(timestamp_ns)  # images a newer one replaces: never pushed
            try:
                self._ahead[timestamp_ns] = self._worker.submit(self._detect, image.copy(),
                                                                index)
            except RuntimeError:  # the worker shut down meanwhile (close)
                return False
        return True

    def read(self, image: np.ndarray, timestamp_ns: int, index: int) -> Future:
        """Return a pushed frame's detection: started ahead for its stamp, else started now.

        Reads started ahead for older stamps (images never pushed) are dropped.
        """
        with self._lock:
            ahead = self._ahead.pop(timestamp_ns, None)
            self._cancel_before(timestamp_ns)
            for stamp in [stamp for stamp in self._ahead if stamp < timestamp_ns]:
                del self._ahead[stamp]  # started already: its result is dropped
        if ahead is not None:
            return ahead
        return self._worker.submit(self._detect, image.copy(), index)

    def _cancel_before(self, timestamp_ns: int) -> None:
        """Cancel the reads started ahead for older stamps that have not started (lock held).

        An image arriving faster than the source reads would otherwise queue up behind them.
        """
        for stamp in [stamp for stamp in self._ahead if stamp < timestamp_ns]:
            if self._ahead[stamp].cancel():
                del self._ahead[stamp]

    def drain(self) -> None:
        """Drop the reads started ahead and wait for the queued ones (reset, close)."""
        with self._lock:
            self._ahead.clear()
        self._worker.submit(lambda: None).result()  # one worker, in order: after the queued

    def reset_source(self) -> None:
        """Reset the hand source in the worker thread (a read started ahead may be running)."""
        self._worker.submit(self._source.reset).result()

    def close(self) -> None:
        """Stop the worker thread (after ``drain``)."""
        self._worker.shutdown(wait=True)

    def _detect(self, image: np.ndarray, index: int) -> FrameDetections:
        """Run the hand source's detection on an image (in the worker thread), timed."""
        with self._timed():
            return self._source.detect(image, index)
