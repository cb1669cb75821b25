"""Rates, latency percentiles and counters (ros/estimator/node_statistics.py)."""

import math

from infinihand_ros.ros.estimator.node_statistics import EstimatorStatistics
import pytest


def test_rates_latencies_and_counters() -> None:
    """10 Hz in, 5 Hz out; latencies 10..50 ms give p50 30 ms and p95 48 ms."""
    stats = EstimatorStatistics(window_s=10.0)
    for i in range(11):
        stats.frame_received(i * 0.1)
    states = ['tracked', 'tracked', 'predicted', 'reinitialised', 'tracked']
    for i, (latency, state) in enumerate(zip([0.01, 0.02, 0.03, 0.04, 0.05], states)):
        stats.frame_published(i * 0.2, latency, latency / 2, state)
    stats.frame_dropped(3)
    stats.frame_bad()
    snap = stats.snapshot(1.0)
    assert snap.input_rate_hz == pytest.approx(10.0)
    assert snap.output_rate_hz == pytest.approx(5.0)
    assert snap.latency_p50_ms == pytest.approx(30.0)
    assert snap.latency_p95_ms == pytest.approx(48.0)
    assert snap.processing_p50_ms == pytest.approx(15.0)
    assert (snap.received, snap.dropped, snap.bad, snap.published) == (11, 3, 1, 5)
    assert snap.seconds_since_input == pytest.approx(0.0)
    assert snap.camera_tracking == {'tracked': 3, 'predicted': 1, 'reinitialised': 1}


def test_window_forgets_old_events_but_not_counts() -> None:
    """Events older than the window leave the rates; counters and the last input stay."""
    stats = EstimatorStatistics(window_s=1.0)
    stats.frame_received(0.0)
    stats.frame_received(0.1)
    stats.frame_published(0.1, 0.05, 0.01, 'tracked')
    snap = stats.snapshot(5.0)
    assert snap.input_rate_hz == 0.0 and snap.output_rate_hz == 0.0
    assert math.isnan(snap.latency_p50_ms)
    assert snap.received == 2 and snap.published == 1
    assert snap.seconds_since_input == pytest.approx(4.9)


def test_nothing_yet() -> None:
    """Before any image: zero rates, NaN latency, infinite time since input."""
    snap = EstimatorStatistics(1.0).snapshot(0.0)
    assert snap.received == 0 and math.isinf(snap.seconds_since_input)


def test_intrinsics_sources_are_counted_per_source() -> None:
    """Each processed frame counts under its intrinsics source; the snapshot is a copy."""
    stats = EstimatorStatistics(1.0)
    for source in ('camera_info', 'camera_info', 'model'):
        stats.intrinsics_used(source)
    snap = stats.snapshot(0.0)
    stats.intrinsics_used('fallback')
    assert snap.intrinsics_sources == {'camera_info': 2, 'model': 1}
    assert stats.snapshot(0.0).intrinsics_sources == {'camera_info': 2, 'model': 1,
                                                      'fallback': 1}


def test_out_of_order_frames_are_counted_apart() -> None:
    """Out-of-order images have their own counter; drops and bad frames stay as they were."""
    stats = EstimatorStatistics(1.0)
    assert stats.snapshot(0.0).out_of_order == 0
    for _ in range(3):
        stats.frame_out_of_order()
    snap = stats.snapshot(0.0)
    assert (snap.out_of_order, snap.dropped, snap.bad) == (3, 0, 0)


def test_stream_restarts_are_counted_apart() -> None:
    """Stream restarts have their own counter; other counters stay as they were."""
    stats = EstimatorStatistics(1.0)
    assert stats.snapshot(0.0).stream_restarts == 0
    stats.stream_restarted()
    snap = stats.snapshot(0.0)
    assert (snap.stream_restarts, snap.out_of_order, snap.dropped, snap.bad) == (1, 0, 0, 0)
