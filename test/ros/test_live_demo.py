"""The live demo (tools/live_demo.py): arguments, the replayed segment, and one short live run."""

from pathlib import Path
import re
import subprocess

from infinihand_ros.eval.prediction_files import read_predictions
from infinihand_ros.tools.node_processes import fresh_domain_id
from infinihand_ros.tools.node_processes import ros_env
from live_processes import LIB
from live_processes import SAMPLE_BAG
import pytest

live_demo = pytest.importorskip('infinihand_ros.tools.live_demo', reason='needs rclpy')

pytestmark = pytest.mark.ros
SECONDS = 4.0
BAG_FPS = 10


@pytest.mark.parametrize('args,message', [
    (['--rate', '0'], '--rate must be > 0'),
    (['--seconds', '-1'], '--seconds must be >= 0'),
    (['--ba', 'always'], 'invalid choice'),
])
def test_bad_arguments_exit_2(args: list[str], message: str, tmp_path: Path,
                              capsys: pytest.CaptureFixture) -> None:
    """Bad arguments exit 2 with a line naming them."""
    with pytest.raises(SystemExit) as done:
        live_demo.parse_args(['--out', str(tmp_path / 'new'), *args])
    assert done.value.code == 2 and message in capsys.readouterr().err


def test_out_must_be_new_or_empty(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A directory with files is refused; an empty one is fine."""
    assert live_demo.parse_args(['--out', str(tmp_path)]).out == tmp_path
    (tmp_path / 'kept.txt').write_text('mine')
    with pytest.raises(SystemExit):
        live_demo.parse_args(['--out', str(tmp_path)])
    assert 'not an empty directory' in capsys.readouterr().err


def test_replayed_stamps_cover_the_first_seconds() -> None:
    """At 10 FPS the first 4 s hold 40 images; 0 means the whole bag (150)."""
    first = live_demo.replayed_stamps(SAMPLE_BAG, SECONDS)
    every = live_demo.replayed_stamps(SAMPLE_BAG, 0.0)
    assert len(first) == SECONDS * BAG_FPS and len(every) == 150
    assert first < every and max(first) < min(every - first)


@pytest.mark.slow
def test_live_demo_end_to_end(tmp_path: Path) -> None:
    """The installed live_demo prints the figures and the tables and writes its files."""
    if not (LIB / 'live_demo').exists():
        pytest.skip('the package is not built (colcon build --symlink-install)')
    out = tmp_path / 'live'
    done = subprocess.run([str(LIB / 'live_demo'), '--out', str(out), '--seconds', f'{SECONDS}'],
                          env=ros_env(fresh_domain_id()), capture_output=True, text=True,
                          timeout=600, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    text = done.stdout
    rate = re.search(r'output rate ([\d.]+) Hz \((\d+) camera poses recorded\)', text)
    assert rate and float(rate.group(1)) > 0 and 0 < int(rate.group(2)) <= SECONDS * BAG_FPS
    assert re.search(r'latency p50 \d+ ms, p95 \d+ ms', text)
    drops = re.search(r'drops: (\d+) dropped by the node .* \((\d+) received\)', text)
    assert drops and int(drops.group(2)) == SECONDS * BAG_FPS
    assert int(drops.group(1)) + int(rate.group(2)) == int(drops.group(2))
    for title in ('**Detection**', '**Camera space**', '**World space**', '**Camera trajectory**'):
        assert title in text
    world = re.search(r'\*\*World space\*\*\n\n.*\n.*\n\| ours \| ([\d.]+) \|', text)
    assert world, text  # W-MPJPE computed from the recorded world joints
    assert '| ours | - | - | - |' in text  # detection: not computed, and said so
    assert 'not computed: FAcc, Recall, F1' in text and 'GO-p' in text
    arrays = read_predictions(out / 'eval' / 'sample_bag.npz')
    assert len(arrays['timestamp_ns']) == SECONDS * BAG_FPS
    assert int(arrays['hand_valid'].any(axis=1).sum()) <= int(rate.group(2))
    assert (out / 'eval' / 'sample_bag_top_view.png').stat().st_size > 0
    assert (out / 'recorded' / 'metadata.yaml').is_file()
