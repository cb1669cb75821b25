"""The generator's command line: clear one-line errors for bad arguments, complete outputs."""

from pathlib import Path
import re

from infinihand_ros.bag.reader import BagReader
from infinihand_ros.core import topics
from infinihand_ros.synth import cli
import pytest
import yaml

SMALL = ['--seed', '1', '--frames', '3', '--width', '96', '--height', '72']


@pytest.mark.parametrize(('args', 'message'), [
    (['--seed', '-1', '--frames', '3'], '--seed must be >= 0, got -1'),
    (['--seed', '1', '--frames', '0'], '--frames must be within 1..1000000, got 0'),
    (['--seed', '1', '--frames', '3', '--width', '10'], 'image size must be within 32..4096 px'),
    (['--seed', '1', '--frames', '3', '--fps', '0'], r'fps must be within \[0.5, 120\]'),
])
def test_bad_arguments_get_one_line_errors(tmp_path: Path, capsys: pytest.CaptureFixture,
                                           args: list[str], message: str) -> None:
    assert cli.main(['--out', str(tmp_path / 'out')] + args) == 2
    error = capsys.readouterr().err
    assert error.startswith('error: ') and error.count('\n') == 1
    assert re.search(message, error)
    assert not (tmp_path / 'out').exists()


@pytest.mark.parametrize(('out', 'message'), [
    ('/proc/infinihand_synth_out', 'cannot create anything in /proc'),
    ('FILE/out', 'FILE is not a directory'),
])
def test_unwritable_output_gets_a_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                 out: str, message: str) -> None:
    file = tmp_path / 'a_file'
    file.write_text('not a directory')
    out, message = out.replace('FILE', str(file)), message.replace('FILE', str(file))
    assert cli.main(['--out', out] + SMALL) == 2
    error = capsys.readouterr().err
    assert error.startswith(f'error: --out {out}: ') and error.count('\n') == 1
    assert message in error
    assert file.read_text() == 'not a directory'


def test_write_failure_during_generation_gets_a_one_line_error(
        tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch) -> None:
    def full_disk(*args: object, **kwargs: object) -> dict:
        raise OSError(28, 'No space left on device')

    monkeypatch.setattr(cli, 'generate', full_disk)
    assert cli.main(['--out', str(tmp_path / 'out')] + SMALL) == 1
    error = capsys.readouterr().err
    assert error.startswith(f"error: writing --out {tmp_path / 'out'} failed: ")
    assert 'No space left on device' in error and error.count('\n') == 1


def test_unknown_choice_is_rejected_by_argparse(tmp_path: Path,
                                                capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exit_info:
        cli.main(['--out', str(tmp_path), '--hands', 'three'] + SMALL)
    assert exit_info.value.code == 2
    assert "invalid choice: 'three'" in capsys.readouterr().err


def test_non_empty_output_and_bad_config_are_refused(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture) -> None:
    (tmp_path / 'old.txt').write_text('keep me')
    assert cli.main(['--out', str(tmp_path)] + SMALL) == 2
    assert 'is not an empty directory' in capsys.readouterr().err
    assert (tmp_path / 'old.txt').read_text() == 'keep me'
    config = tmp_path / 'bad.yaml'
    config.write_text('synth: {fps: fast}\nbag: {}\n')
    assert cli.main(['--out', str(tmp_path / 'new'), '--config', str(config)] + SMALL) == 2
    assert 'synth.fps: expected a number' in capsys.readouterr().err


def test_small_run_writes_every_output(tmp_path: Path) -> None:
    out = tmp_path / 'seq'
    assert cli.main(['--out', str(out), '--image-codec', 'png', '--hands', 'left'] + SMALL) == 0
    for name in (cli.FRAMES_PREVIEW, cli.TRAJECTORY_PREVIEW):
        assert (out / name).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    resolved = yaml.safe_load((out / cli.RESOLVED_CONFIG).read_text())
    assert resolved['synth']['width'] == 96 and resolved['synth']['hands'] == 'left'
    assert resolved['bag']['image_codec'] == 'png' and resolved['seed'] == 1
    with BagReader(out / cli.BAG_DIR) as reader:
        counts = {topic: info.count for topic, info in reader.topics().items()}
    assert counts == {topics.COMPRESSED_IMAGE_TOPIC: 3, topics.CAMERA_INFO_TOPIC: 3,
                      topics.GT_CAMERA_POSE_TOPIC: 3, topics.GT_HANDS_TOPIC: 3}
    assert (out / cli.SAMPLES_DIR).is_dir()
