"""The estimator's ``/diagnostics`` status: level, message and key/value pairs (no ROS types).

Level OK while images arrive and are published; WARN when no image came for a whole statistics
window, when images are being dropped, refused or skipped as out of order (a stamp not after
the last accepted image's) in that time, when the stream restarted then (a stamp far before the
last accepted one: the engine reset, a new world frame), when bundle adjustment has failed, or
when the bundle-adjustment node is not there (never seen, or lost): poses continue unrefined
then, and when the camera tracker could not measure published frames in the image (their
poses follow the network's motion) or restarted (a discontinuity: a cut, or the view lost for
several frames). STALE before the first image. The values include how many frames took their
intrinsics from a paired CameraInfo, the fallback and the model (``intrinsics_from_*``): frames
counted under ``model`` while a camera publishes CameraInfos mean that pairing is failing;
``lens_provisional``: a fixed camera's lens is still being estimated beside the stream (its
frames go out with a provisional one, flagged ``provisional_intrinsics`` in their results). The
engine's pacing (``engine/pacing.py``): the geometry interval it runs, whether it is chosen from
measured cost, the costs, the input's frame period and the share of it the engine fills
(``utilisation``).
"""

from dataclasses import dataclass
import math
from typing import Final

from infinihand_ros.engine import camera_tracker
from infinihand_ros.ros.estimator.camera_info_pairing import FROM_CAMERA_INFO
from infinihand_ros.ros.estimator.camera_info_pairing import FROM_FALLBACK
from infinihand_ros.ros.estimator.camera_info_pairing import FROM_MODEL
from infinihand_ros.ros.estimator.node_statistics import OK
from infinihand_ros.ros.estimator.node_statistics import STALE
from infinihand_ros.ros.estimator.node_statistics import StatisticsSnapshot
from infinihand_ros.ros.estimator.node_statistics import WARN

#: States of the link to the bundle-adjustment node (``ba_node_client.BANodeLink``).
WAITING: Final = 'waiting'
CONNECTED: Final = 'connected'
LOST: Final = 'lost'
#: Link states in which poses go on unrefined, and how diagnostics say so.
UNAVAILABLE: Final = {WAITING: 'not seen yet', LOST: 'lost'}
#: Intrinsics sources, each reported as ``intrinsics_from_<source>`` (frames since start).
INTRINSICS_SOURCES: Final = (FROM_CAMERA_INFO, FROM_FALLBACK, FROM_MODEL)
#: Camera-tracking states, each reported as ``camera_<state>`` (published frames since start).
TRACKING_STATES: Final = (*camera_tracker.TRACKING_STATES, 'static')


@dataclass(frozen=True)
class DiagnosticReport:
    """One diagnostic_msgs/DiagnosticStatus: level, message and ordered key/value strings."""

    level: int
    message: str
    values: tuple[tuple[str, str], ...]


def ba_state(engine_statistics: dict[str, object]) -> str:
    """Return the BA state of the engine's statistics ('off' when the engine runs no BA)."""
    ba = engine_statistics.get('ba')
    return 'off' if not isinstance(ba, dict) else str(ba.get('state', 'unknown'))


def _ba_count(engine_statistics: dict[str, object], key: str) -> object:
    """Return a BA counter of the statistics (0 without BA)."""
    ba = engine_statistics.get('ba')
    return ba.get(key, 0) if isinstance(ba, dict) else 0


def _tracker_ms(engine_statistics: dict[str, object]) -> float:
    """Return the camera tracker's mean cost per frame, ms (NaN when not reported)."""
    tracker = engine_statistics.get('tracker')
    return (float(tracker.get('ms_per_frame', float('nan'))) if isinstance(tracker, dict)
            else float('nan'))


def _pacing_values(engine_statistics: dict[str, object]) -> tuple[tuple[str, object], ...]:
    """Return the engine's pacing figures (``engine/pacing.py``): interval, costs, utilisation."""
    pacing = engine_statistics.get('pacing')
    if not isinstance(pacing, dict):
        return ()
    nan = float('nan')
    return (('geometry_interval', pacing.get('geometry_interval', 0)),
            ('geometry_interval_paced', pacing.get('paced', False)),
            ('geometry_lag', pacing.get('geometry_lag', 0)),
            *((key, nan if pacing.get(key) is None else float(pacing[key]))
              for key in ('frame_ms', 'geometry_ms', 'period_ms', 'utilisation')))


def _format(value: object) -> str:
    """Return a figure as diagnostics text (floats with 3 decimals, NaN as 'nan')."""
    if isinstance(value, float):
        return 'nan' if math.isnan(value) else f'{value:.3f}'
    return str(value)


def diagnostic_report(snapshot: StatisticsSnapshot, engine_statistics: dict[str, object],
                      window_s: float, previous: StatisticsSnapshot | None = None
                      ) -> DiagnosticReport:
    """Return the status of the node from its figures and the engine's statistics.

    Args:
        snapshot: the node's figures now.
        engine_statistics: ``StreamingEngine.statistics`` (metric scale, BA state); with the
            BA node, its ``ba`` entry is the ``BANodeLink`` statistics.
        window_s: the statistics window, seconds (no image for this long: WARN).
        previous: the figures of the last report, to tell new drops, bad and out-of-order
            frames and stream restarts; None for the first report (those since the start are
            new).

    """
    state = ba_state(engine_statistics)
    values = (
        ('input_rate_hz', snapshot.input_rate_hz), ('output_rate_hz', snapshot.output_rate_hz),
        ('latency_p50_ms', snapshot.latency_p50_ms), ('latency_p95_ms', snapshot.latency_p95_ms),
        ('processing_p50_ms', snapshot.processing_p50_ms),
        ('processing_p95_ms', snapshot.processing_p95_ms),
        ('frames_received', snapshot.received), ('frames_published', snapshot.published),
        ('frames_dropped', snapshot.dropped), ('bad_frames', snapshot.bad),
        ('frames_out_of_order', snapshot.out_of_order),
        ('stream_restarts', snapshot.stream_restarts),
        ('metric_scale', engine_statistics.get('metric_scale', float('nan'))),
        ('metric_scale_state', engine_statistics.get('metric_scale_state', 'unknown')),
        ('pose_version', engine_statistics.get('pose_version', 0)), ('ba_state', state),
        ('ba_calls_submitted', _ba_count(engine_statistics, 'submitted')),
        ('ba_calls_done', _ba_count(engine_statistics, 'done')),
        ('ba_results_applied', _ba_count(engine_statistics, 'folded_in')),
        ('ba_outages', _ba_count(engine_statistics, 'outages')),
        *((f'intrinsics_from_{source}', snapshot.intrinsics_sources.get(source, 0))
          for source in INTRINSICS_SOURCES),
        *((f'camera_{state}', snapshot.camera_tracking.get(state, 0))
          for state in TRACKING_STATES),
        ('tracker_ms_per_frame', _tracker_ms(engine_statistics)),
        ('frames_with_depth', engine_statistics.get('frames_with_depth', 0)),
        ('frames_without_geometry', engine_statistics.get('frames_without_geometry', 0)),
        ('geometry_failures', engine_statistics.get('geometry_failures', 0)),
        ('lens_provisional', engine_statistics.get('lens_provisional', False)),
        *_pacing_values(engine_statistics))
    text = tuple((key, _format(value)) for key, value in values)
    if snapshot.received == 0:
        return DiagnosticReport(STALE, 'waiting for images', text)
    problems = []
    if snapshot.seconds_since_input > window_s:
        problems.append(f'no image for {snapshot.seconds_since_input:.1f} s')
    dropped_before, bad_before, late_before, restarts_before = (
        (0, 0, 0, 0) if previous is None else
        (previous.dropped, previous.bad, previous.out_of_order, previous.stream_restarts))
    if snapshot.dropped > dropped_before:
        problems.append(f'{snapshot.dropped - dropped_before} frame(s) dropped (input faster '
                        'than the model)')
    if snapshot.bad > bad_before:
        problems.append(f'{snapshot.bad - bad_before} bad frame(s) skipped')
    if snapshot.out_of_order > late_before:
        problems.append(f'{snapshot.out_of_order - late_before} frame(s) out of order skipped '
                        '(stamp not after the last accepted one)')
    if snapshot.stream_restarts > restarts_before:
        problems.append(f'stream restarted {snapshot.stream_restarts - restarts_before} '
                        'time(s) (stamp far before the last accepted one: a replay loop or a '
                        'camera restart): the world frame restarted')
    tracking_before = {} if previous is None else previous.camera_tracking
    new = {key: snapshot.camera_tracking.get(key, 0) - tracking_before.get(key, 0)
           for key in ('predicted', 'reinitialised')}
    if new['predicted'] > 0:
        problems.append(f"camera not tracked in {new['predicted']} frame(s): poses follow the "
                        "network's motion (textureless, covered or blurred view)")
    if new['reinitialised'] > 0:
        problems.append(f"camera track restarted {new['reinitialised']} time(s): poses are "
                        'not continuous there (a cut, or the view lost)')
    if state == 'failed':
        problems.append('bundle adjustment failed: poses are unrefined')
    if state in UNAVAILABLE:
        problems.append(f'bundle-adjustment node {UNAVAILABLE[state]}: poses are unrefined')
    if problems:
        return DiagnosticReport(WARN, '; '.join(problems), text)
    return DiagnosticReport(OK, 'running', text)
