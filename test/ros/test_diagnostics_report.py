"""The /diagnostics status (ros/estimator/diagnostics.py)."""

from dataclasses import replace

from infinihand_ros.ros.estimator.diagnostics import ba_state
from infinihand_ros.ros.estimator.diagnostics import diagnostic_report
from infinihand_ros.ros.estimator.node_statistics import OK
from infinihand_ros.ros.estimator.node_statistics import STALE
from infinihand_ros.ros.estimator.node_statistics import StatisticsSnapshot
from infinihand_ros.ros.estimator.node_statistics import WARN

RUNNING = StatisticsSnapshot(10.0, 9.5, 40.0, 80.0, 20.0, 30.0, 100, 0, 0, 95, 0.05)
ENGINE = {'metric_scale': 0.25, 'metric_scale_state': 'tracking', 'pose_version': 4, 'ba': None}


def test_running_is_ok_with_the_figures() -> None:
    """All figures appear as text; the level is OK."""
    report = diagnostic_report(RUNNING, ENGINE, 5.0, RUNNING)
    values = dict(report.values)
    assert report.level == OK
    assert values['input_rate_hz'] == '10.000' and values['latency_p95_ms'] == '80.000'
    assert values['metric_scale'] == '0.250' and values['ba_state'] == 'off'
    assert values['frames_dropped'] == '0' and values['bad_frames'] == '0'
    assert values['frames_out_of_order'] == '0' and values['stream_restarts'] == '0'
    assert [values[f'intrinsics_from_{source}'] for source in ('camera_info', 'fallback',
                                                               'model')] == ['0', '0', '0']


def test_intrinsics_sources_appear_with_zeros_for_unused_ones() -> None:
    """Every source is a value; one never used reads 0."""
    snapshot = replace(RUNNING, intrinsics_sources={'camera_info': 90, 'model': 5})
    values = dict(diagnostic_report(snapshot, ENGINE, 5.0, RUNNING).values)
    assert (values['intrinsics_from_camera_info'], values['intrinsics_from_fallback'],
            values['intrinsics_from_model']) == ('90', '0', '5')


def test_warnings_name_their_cause() -> None:
    """New drops, new bad frames, no input and a failed BA each give WARN with a reason."""
    dropped = replace(RUNNING, dropped=4, bad=1, seconds_since_input=9.0)
    report = diagnostic_report(dropped, {**ENGINE, 'ba': {'state': 'failed'}}, 5.0, RUNNING)
    assert report.level == WARN
    for text in ('4 frame(s) dropped', '1 bad frame(s)', 'no image for 9.0 s',
                 'bundle adjustment failed'):
        assert text in report.message


def test_first_report_counts_drops_since_the_start() -> None:
    """A burst before the first report (no previous figures) still warns of its drops."""
    report = diagnostic_report(replace(RUNNING, dropped=7, bad=2), ENGINE, 5.0)
    assert report.level == WARN
    assert '7 frame(s) dropped' in report.message and '2 bad frame(s)' in report.message


def test_out_of_order_frames_warn_while_new() -> None:
    """New out-of-order frames: a value and WARN naming them; none new: OK, the count stays."""
    late = replace(RUNNING, out_of_order=3)
    report = diagnostic_report(late, ENGINE, 5.0, RUNNING)
    assert report.level == WARN and '3 frame(s) out of order skipped' in report.message
    assert dict(report.values)['frames_out_of_order'] == '3'
    later = diagnostic_report(late, ENGINE, 5.0, late)
    assert later.level == OK and dict(later.values)['frames_out_of_order'] == '3'


def test_stream_restarts_warn_while_new() -> None:
    """A new stream restart: a value and WARN saying the world frame restarted; later: OK."""
    restarted = replace(RUNNING, stream_restarts=1)
    report = diagnostic_report(restarted, ENGINE, 5.0, RUNNING)
    assert report.level == WARN and 'stream restarted 1 time(s)' in report.message
    assert 'the world frame restarted' in report.message
    assert dict(report.values)['stream_restarts'] == '1'
    assert diagnostic_report(restarted, ENGINE, 5.0).level == WARN  # since the start: new
    later = diagnostic_report(restarted, ENGINE, 5.0, restarted)
    assert later.level == OK and dict(later.values)['stream_restarts'] == '1'


def test_camera_tracking_counts_and_new_untracked_frames_warn() -> None:
    """Published frames per tracking state are values; new predicted or restarts warn."""
    tracked = replace(RUNNING, camera_tracking={'tracked': 95})
    engine = {**ENGINE, 'tracker': {'states': {'tracked': 95}, 'ms_per_frame': 4.25}}
    report = diagnostic_report(tracked, engine, 5.0, tracked)
    values = dict(report.values)
    assert report.level == OK
    assert (values['camera_tracked'], values['camera_predicted'], values['camera_reinitialised'],
            values['camera_static'], values['tracker_ms_per_frame']) == ('95', '0', '0', '0',
                                                                         '4.250')
    lost = replace(RUNNING, camera_tracking={'tracked': 95, 'predicted': 4, 'reinitialised': 1})
    report = diagnostic_report(lost, engine, 5.0, tracked)
    assert report.level == WARN
    assert 'camera not tracked in 4 frame(s)' in report.message
    assert 'camera track restarted 1 time(s)' in report.message
    assert diagnostic_report(lost, engine, 5.0, lost).level == OK
    assert dict(diagnostic_report(RUNNING, ENGINE, 5.0).values)['tracker_ms_per_frame'] == 'nan'


def test_model_work_skipped_is_counted() -> None:
    """Frames that ran the depth head, frames without the geometry branch, its failures."""
    engine = {**ENGINE, 'frames_with_depth': 12, 'frames_without_geometry': 80,
              'geometry_failures': 1}
    keys = ('frames_with_depth', 'frames_without_geometry', 'geometry_failures')
    values = dict(diagnostic_report(RUNNING, engine, 5.0, RUNNING).values)
    assert tuple(values[key] for key in keys) == ('12', '80', '1')
    values = dict(diagnostic_report(RUNNING, ENGINE, 5.0, RUNNING).values)
    assert tuple(values[key] for key in keys) == ('0', '0', '0')


def test_stale_before_the_first_image() -> None:
    """No image received yet: STALE."""
    report = diagnostic_report(replace(RUNNING, received=0), ENGINE, 5.0)
    assert report.level == STALE


def test_ba_state() -> None:
    """The BA state comes from the engine statistics."""
    assert ba_state({'ba': {'state': 'running'}}) == 'running'
    assert ba_state({'ba': None}) == 'off'


def test_in_process_ba_calls_are_counted() -> None:
    """The in-process worker's submitted and finished calls are values (0 without BA)."""
    ba = {'state': 'idle', 'submitted': 5, 'done': 4, 'folded_in': 3}
    values = dict(diagnostic_report(RUNNING, {**ENGINE, 'ba': ba}, 5.0, RUNNING).values)
    assert (values['ba_calls_submitted'], values['ba_calls_done'],
            values['ba_results_applied']) == ('5', '4', '3')
    values = dict(diagnostic_report(RUNNING, ENGINE, 5.0, RUNNING).values)
    assert (values['ba_calls_submitted'], values['ba_calls_done']) == ('0', '0')


def test_an_absent_or_lost_ba_node_warns_and_counts_show() -> None:
    """Node link 'waiting' or 'lost': WARN saying poses are unrefined; counters as values."""
    for state, text in (('waiting', 'not seen yet'), ('lost', 'lost')):
        ba = {'state': state, 'folded_in': 3, 'outages': 1}
        report = diagnostic_report(RUNNING, {**ENGINE, 'ba': ba}, 5.0, RUNNING)
        assert report.level == WARN
        assert f'bundle-adjustment node {text}: poses are unrefined' in report.message
        values = dict(report.values)
        assert values['ba_state'] == state and values['ba_results_applied'] == '3'
        assert values['ba_outages'] == '1'
    connected = {'state': 'connected', 'folded_in': 4, 'outages': 1}
    assert diagnostic_report(RUNNING, {**ENGINE, 'ba': connected}, 5.0, RUNNING).level == OK
