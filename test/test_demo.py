"""The demo (``make demo``) reproduces the embedded sample bag and evaluates the bundled model."""

from pathlib import Path
import re

from infinihand_ros import demo
from infinihand_ros.eval.prediction_files import read_predictions
from infinihand_ros.synth import cli
import pytest

#: Images of the 150 replayed the live node must receive (a few may be lost under load).
MIN_RECEIVED = 140


@pytest.mark.slow
@pytest.mark.ros
def test_demo_regenerates_the_sample_bag_and_evaluates(tmp_path: Path,
                                                       capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / 'demo'
    out.mkdir()
    (out / demo.OUTPUT_MARKER).write_text('an earlier demo run')
    (out / 'stale.txt').write_text('from an earlier run')
    assert demo.main(['--out', str(out)]) == 0
    report = capsys.readouterr().out
    assert 'ground truth identical to the bag: True' in report
    assert '150 x infinihand_msgs/msg/HandFrame' in report
    assert ('Engine (tiny_synthetic, per_frame mode, bundle adjustment on, final trajectory) '
            'on the bag') in report
    for table in ('**Detection**', '**World space**', '**Camera trajectory**'):
        assert table in report
    assert '| static-camera |' in report and '| mean-hand |' in report
    assert 'mean pose: training set' in report
    evaluated = out / demo.EVAL_DIR
    assert read_predictions(evaluated / 'sample_bag.npz')['T_world_cam'].shape == (150, 4, 4)
    assert (evaluated / 'sample_bag_top_view.png').stat().st_size > 0
    # The live path: replay -> estimator node -> record, evaluated the same way.
    assert 'Live estimator (bundle adjustment none' in report
    assert '150 images replayed at 10 Hz' in report
    # Best-effort images (sensor-data QoS) can be lost in transport on a busy machine; the
    # report counts them. Nearly all must arrive.
    received = int(re.search(r'\((\d+) received\)', report).group(1))
    assert MIN_RECEIVED <= received <= 150, report
    assert report.count('**World space**') == 2
    side_by_side = report[report.index('Offline and live side by side:'):]
    for row in ('| offline: engine + BA, final trajectory | ',
                '| live node at 10 Hz, as published (', '| still camera | ',
                '| constant skeleton (mean hand) | '):
        assert row in side_by_side
    assert (out / demo.LIVE_DIR / 'eval' / 'sample_bag.npz').is_file()
    assert str(out / demo.LIVE_DIR) in report and '/.demo' not in report
    assert not (out / 'stale.txt').exists()
    assert (out / demo.OUTPUT_MARKER).is_file()
    for name in (cli.FRAMES_PREVIEW, cli.TRAJECTORY_PREVIEW, cli.RESOLVED_CONFIG):
        assert (out / name).stat().st_size > 0
    assert [p.name for p in tmp_path.iterdir()] == ['demo']


def test_demo_refuses_a_directory_it_did_not_write(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / 'mine'
    out.mkdir()
    (out / 'thesis.tex').write_text('keep me')
    assert demo.main(['--out', str(out)]) == 2
    error = capsys.readouterr().err
    assert error == (f'error: --out {out} holds files the demo did not write (no '
                     '.infinihand_demo marker) and would be replaced; choose another path or '
                     'empty it yourself\n')
    assert [p.name for p in out.iterdir()] == ['thesis.tex']
    assert (out / 'thesis.tex').read_text() == 'keep me'


@pytest.mark.parametrize(('out', 'message'), [
    ('FILE', 'FILE is a file, not a directory'),
    ('FILE/demo', 'FILE is not a directory'),
    ('/proc/infinihand_demo_out', 'cannot create anything in /proc'),
])
def test_demo_refuses_an_unusable_output_path(tmp_path: Path, capsys: pytest.CaptureFixture,
                                              out: str, message: str) -> None:
    file = tmp_path / 'a_file'
    file.write_text('not a directory')
    out, message = out.replace('FILE', str(file)), message.replace('FILE', str(file))
    assert demo.main(['--out', out]) == 2
    error = capsys.readouterr().err
    assert error.startswith(f'error: --out {out}') and error.count('\n') == 1
    assert message in error
    assert file.read_text() == 'not a directory'
