"""The batch generator: the single-sequence command's samples, resumable, clear errors."""

from pathlib import Path

from infinihand_ros.synth import batch
from infinihand_ros.synth import cli
import pytest

SIZE = ['--frames', '3', '--width', '96', '--height', '72', '--fps', '15']


def _files(samples: Path) -> dict[str, bytes]:
    return {str(path.relative_to(samples)): path.read_bytes()
            for path in sorted(samples.rglob('*')) if path.is_file()}


def test_samples_equal_the_single_sequence_command(tmp_path: Path) -> None:
    assert batch.main(['--out', str(tmp_path / 'batch'), '--seeds', '4', '5'] + SIZE) == 0
    assert cli.main(['--out', str(tmp_path / 'one'), '--seed', '5'] + SIZE) == 0
    written = _files(tmp_path / 'batch' / 'seed_5' / 'samples')
    assert written == _files(tmp_path / 'one' / 'samples')
    assert {'meta.json', 'annotations.safetensors', 'rgb/000002.jpg'} <= set(written)
    assert sorted(p.name for p in (tmp_path / 'batch').iterdir()) == ['seed_4', 'seed_5']


def test_a_rerun_skips_written_seeds_and_redoes_partial_ones(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / 'batch'
    assert batch.main(['--out', str(out), '--seeds', '0', '1'] + SIZE) == 0
    kept = out / 'seed_0' / 'samples' / 'annotations.safetensors'
    stamp = kept.stat().st_mtime_ns
    redone = out / 'seed_1'
    expected = _files(redone / 'samples')
    for path in sorted(redone.rglob('*'), reverse=True):  # as if interrupted before the move
        path.unlink() if path.is_file() else path.rmdir()
    (redone / 'leftover').write_text('partial')
    capsys.readouterr()
    assert batch.main(['--out', str(out), '--seeds', '0', '1'] + SIZE) == 0
    assert 'wrote 1 of 2 sequences' in capsys.readouterr().out
    assert kept.stat().st_mtime_ns == stamp
    assert _files(redone / 'samples') == expected
    assert not (redone / 'leftover').exists()


@pytest.mark.parametrize(('args', 'message'), [
    (['--seeds', '3', '2', '--frames', '3'], '--seeds: expected 0 <= FIRST <= LAST, got 3 2'),
    (['--seeds', '-1', '2', '--frames', '3'], '--seeds: expected 0 <= FIRST <= LAST, got -1 2'),
    (['--seeds', '1', '2', '--frames', '0'], '--frames must be at least 1, got 0'),
])
def test_bad_arguments_get_one_line_errors(tmp_path: Path, capsys: pytest.CaptureFixture,
                                           args: list[str], message: str) -> None:
    assert batch.main(['--out', str(tmp_path / 'out')] + args) == 2
    assert capsys.readouterr().err.strip() == f'error: {message}'
    assert not (tmp_path / 'out').exists()


def test_an_output_that_is_a_file_is_refused(tmp_path: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    target = tmp_path / 'file'
    target.write_text('x')
    assert batch.main(['--out', str(target), '--seeds', '0', '0', '--frames', '3']) == 2
    assert 'is not a directory' in capsys.readouterr().err
