"""The demo (``make demo``) runs on the embedded sample bag and reproduces it."""

from pathlib import Path

from infinihand_ros import demo
from infinihand_ros.synth import cli
import pytest


@pytest.mark.slow
def test_demo_regenerates_the_sample_bag(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / 'demo'
    out.mkdir()
    (out / 'stale.txt').write_text('from an earlier run')
    assert demo.main(['--out', str(out)]) == 0
    report = capsys.readouterr().out
    assert 'ground truth identical to the bag: True' in report
    assert '150 x infinihand_msgs/msg/HandFrame' in report
    assert '150 results for 150 frames' in report
    assert not (out / 'stale.txt').exists()
    for name in (cli.FRAMES_PREVIEW, cli.TRAJECTORY_PREVIEW, cli.RESOLVED_CONFIG):
        assert (out / name).stat().st_size > 0
