"""The estimator's running figures for ``/diagnostics``: rates, latency, drops, bad frames.

Rates and latency percentiles cover the last ``window_s`` seconds: a rate is (events - 1) over
the time between the first and last event in the window (0 with fewer than two), so it is right
from the second frame on. Latency is measured from the image stamp to the publication of its
outputs, on the node's clock (ROS time; ``/clock`` when replaying with ``use_sim_time``), and
from the image's arrival at the node to that publication (the node's own share, any clock).
Counters (received, dropped, bad, published, out of order, stream restarts, and the frames
processed with intrinsics from each source: a paired CameraInfo, the configured fallback, the
model's field of view) count since start. Thread-safe: the image callback and the inference
thread report concurrently.
"""

from collections import deque
from dataclasses import dataclass
from dataclasses import field
import threading
from typing import Final

import numpy as np

#: diagnostic_msgs/DiagnosticStatus levels.
OK: Final = 0
WARN: Final = 1
ERROR: Final = 2
STALE: Final = 3
MS_PER_S: Final = 1e3


@dataclass(frozen=True)
class StatisticsSnapshot:
    """The figures at one moment.

    Attributes:
        input_rate_hz: images received per second (recent window).
        output_rate_hz: frames published per second (recent window).
        latency_p50_ms: median image-stamp-to-publication latency, ms (NaN: none yet).
        latency_p95_ms: 95th percentile of that latency, ms (NaN: none yet).
        processing_p50_ms: median arrival-to-publication time, ms (NaN: none yet).
        processing_p95_ms: 95th percentile of that time, ms (NaN: none yet).
        received: images received since start.
        dropped: images replaced by a newer one before inference took them.
        bad: images (or CameraInfos) refused as malformed.
        published: frames published.
        seconds_since_input: time since the last image, s (inf: none yet).
        intrinsics_sources: frames processed per intrinsics source (``camera_info_pairing``'s
            ``FROM_CAMERA_INFO``, ``FROM_FALLBACK``, ``FROM_MODEL``), since start.
        out_of_order: images skipped because their stamp was not after the last accepted
            image's (late or repeated), since start.
        camera_tracking: frames published per camera-tracking state (``FrameResult.tracking``:
            tracked, predicted, reinitialised, static), since start.
        stream_restarts: images stamped far before the last accepted one that started a new
            stream (the engine reset, a new world frame), since start.

    """

    input_rate_hz: float
    output_rate_hz: float
    latency_p50_ms: float
    latency_p95_ms: float
    processing_p50_ms: float
    processing_p95_ms: float
    received: int
    dropped: int
    bad: int
    published: int
    seconds_since_input: float
    intrinsics_sources: dict[str, int] = field(default_factory=dict)
    out_of_order: int = 0
    camera_tracking: dict[str, int] = field(default_factory=dict)
    stream_restarts: int = 0


def _rate(times: deque[float]) -> float:
    """Return events per second of the time-sorted ``times`` (0 with fewer than two)."""
    if len(times) < 2 or times[-1] <= times[0]:
        return 0.0
    return (len(times) - 1) / (times[-1] - times[0])


def _percentiles_ms(values_s: list[float]) -> tuple[float, float]:
    """Return the 50th and 95th percentiles of seconds, in ms (NaN for no values)."""
    if not values_s:
        return float('nan'), float('nan')
    p50, p95 = np.percentile(np.array(values_s), [50.0, 95.0]) * MS_PER_S
    return float(p50), float(p95)


class EstimatorStatistics:
    """Counters and windows of the node's figures."""

    def __init__(self, window_s: float) -> None:
        """Start with no events; rates and latencies look back ``window_s`` seconds."""
        self.window_s = window_s
        self._lock = threading.Lock()
        self._inputs: deque[float] = deque()
        self._outputs: deque[tuple[float, float, float]] = deque()  # (time, latencies)
        self._counts = {'received': 0, 'dropped': 0, 'bad': 0, 'published': 0,
                        'out_of_order': 0, 'stream_restarts': 0}
        self._last_input_s: float | None = None
        self._intrinsics_sources: dict[str, int] = {}
        self._camera_tracking: dict[str, int] = {}

    def frame_received(self, now_s: float) -> None:
        """Count an image that arrived at ``now_s``."""
        with self._lock:
            self._counts['received'] += 1
            self._inputs.append(now_s)
            self._last_input_s = now_s
            self._trim(now_s)

    def frame_dropped(self, count: int = 1) -> None:
        """Count images dropped unprocessed."""
        with self._lock:
            self._counts['dropped'] += count

    def frame_bad(self) -> None:
        """Count a malformed message."""
        with self._lock:
            self._counts['bad'] += 1

    def frame_out_of_order(self) -> None:
        """Count an image skipped for a stamp not after the last accepted one."""
        with self._lock:
            self._counts['out_of_order'] += 1

    def stream_restarted(self) -> None:
        """Count an image that started a new stream (its stamp far before the last one)."""
        with self._lock:
            self._counts['stream_restarts'] += 1

    def intrinsics_used(self, source: str) -> None:
        """Count a frame processed with intrinsics from ``source``."""
        with self._lock:
            self._intrinsics_sources[source] = self._intrinsics_sources.get(source, 0) + 1

    def frame_published(self, now_s: float, latency_s: float, processing_s: float,
                        tracking: str) -> None:
        """Count a frame published at ``now_s``.

        Args:
            now_s: publication time, s (node clock).
            latency_s: time since the image's stamp, s.
            processing_s: time since the image arrived at the node, s.
            tracking: how its camera pose was found (``FrameResult.tracking``).

        """
        with self._lock:
            self._counts['published'] += 1
            self._camera_tracking[tracking] = self._camera_tracking.get(tracking, 0) + 1
            self._outputs.append((now_s, latency_s, processing_s))
            self._trim(now_s)

    def snapshot(self, now_s: float) -> StatisticsSnapshot:
        """Return the figures at ``now_s``."""
        with self._lock:
            self._trim(now_s)
            latency = _percentiles_ms([latency for _, latency, _ in self._outputs])
            processing = _percentiles_ms([processing for _, _, processing in self._outputs])
            last_input = self._last_input_s
            return StatisticsSnapshot(
                _rate(self._inputs), _rate(deque(t for t, _, _ in self._outputs)), *latency,
                *processing, self._counts['received'], self._counts['dropped'],
                self._counts['bad'], self._counts['published'],
                float('inf') if last_input is None else now_s - last_input,
                dict(self._intrinsics_sources), self._counts['out_of_order'],
                dict(self._camera_tracking), self._counts['stream_restarts'])

    def _trim(self, now_s: float) -> None:
        """Drop events older than the window (caller holds the lock)."""
        start = now_s - self.window_s
        while self._inputs and self._inputs[0] < start:
            self._inputs.popleft()
        while self._outputs and self._outputs[0][0] < start:
            self._outputs.popleft()
