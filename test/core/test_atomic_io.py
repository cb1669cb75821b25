"""Atomic writes: complete outputs or none, earlier outputs kept on failure, umask honoured."""

import os
from pathlib import Path

from infinihand_ros.core import atomic_io
from infinihand_ros.core.atomic_io import atomic_directory
from infinihand_ros.core.atomic_io import atomic_write_bytes
from infinihand_ros.core.atomic_io import check_writable_location
from infinihand_ros.core.errors import InputError
import pytest


def test_file_write_replaces_and_honours_the_umask(tmp_path: Path) -> None:
    path = tmp_path / 'sub' / 'out.bin'
    atomic_write_bytes(path, b'one')
    atomic_write_bytes(path, b'two')
    assert path.read_bytes() == b'two'
    assert path.stat().st_mode & 0o777 == 0o666 & ~_umask()
    assert [p.name for p in path.parent.iterdir()] == ['out.bin']


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_failed_directory_write_keeps_the_old_output(tmp_path: Path) -> None:
    final = tmp_path / 'result'
    final.mkdir()
    (final / 'old.txt').write_text('old')
    with pytest.raises(RuntimeError, match='interrupted'):
        with atomic_directory(final, overwrite=True) as work:
            work.mkdir()
            (work / 'new.txt').write_text('half')
            raise RuntimeError('interrupted')
    assert [p.name for p in tmp_path.iterdir()] == ['result']
    assert [p.name for p in final.iterdir()] == ['old.txt']


def test_directory_write_moves_into_place(tmp_path: Path) -> None:
    final = tmp_path / 'result'
    with atomic_directory(final) as work:
        assert not work.exists()
        work.mkdir()
        (work / 'new.txt').write_text('new')
    assert (final / 'new.txt').read_text() == 'new'
    with pytest.raises(InputError, match='already exists'):
        with atomic_directory(final):
            pass


def _old_output(tmp_path: Path) -> Path:
    final = tmp_path / 'result'
    (final / 'sub').mkdir(parents=True)
    (final / 'old.txt').write_text('old')
    (final / 'sub' / 'deep.txt').write_text('deep')
    return final


def _assert_old_output_intact(tmp_path: Path, final: Path) -> None:
    assert [p.name for p in tmp_path.iterdir()] == ['result']
    assert sorted(p.name for p in final.iterdir()) == ['old.txt', 'sub']
    assert (final / 'old.txt').read_text() == 'old'
    assert (final / 'sub' / 'deep.txt').read_text() == 'deep'


def test_overwrite_replaces_the_contents_and_leaves_no_siblings(tmp_path: Path) -> None:
    final = _old_output(tmp_path)
    with atomic_directory(final, overwrite=True) as work:
        work.mkdir()
        (work / 'new.txt').write_text('new')
        assert (final / 'old.txt').read_text() == 'old'  # untouched until the block succeeds
    assert [p.name for p in tmp_path.iterdir()] == ['result']
    assert [p.name for p in final.iterdir()] == ['new.txt']


def test_failed_rename_in_puts_the_old_output_back(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    final = _old_output(tmp_path)
    real_replace = os.replace
    calls = []

    def failing_replace(source: str | Path, target: str | Path) -> None:
        calls.append((Path(source), Path(target)))
        if len(calls) == 2:  # the first call moved the old output away; fail the new one's
            raise OSError('disk on fire')
        real_replace(source, target)

    monkeypatch.setattr(atomic_io.os, 'replace', failing_replace)
    with pytest.raises(OSError, match='disk on fire'):
        with atomic_directory(final, overwrite=True) as work:
            work.mkdir()
            (work / 'new.txt').write_text('new')
    assert calls[0][0] == final and calls[0][1].name.startswith('.result.')
    _assert_old_output_intact(tmp_path, final)


def test_block_that_writes_nothing_keeps_the_old_output(tmp_path: Path) -> None:
    final = _old_output(tmp_path)
    with pytest.raises(FileNotFoundError):
        with atomic_directory(final, overwrite=True):
            pass
    _assert_old_output_intact(tmp_path, final)


def test_failed_restore_keeps_the_old_output_beside_and_says_where(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    final = _old_output(tmp_path)
    real_replace = os.replace

    def replace_once(source: str | Path, target: str | Path) -> None:
        if Path(target) == final:
            raise OSError('read-only now')
        real_replace(source, target)

    monkeypatch.setattr(atomic_io.os, 'replace', replace_once)
    with pytest.raises(OSError, match='read-only now') as error:
        with atomic_directory(final, overwrite=True) as work:
            work.mkdir()
    (kept,) = tmp_path.iterdir()
    assert kept.name.startswith('.result.') and kept.name.endswith('.old')
    assert (kept / 'sub' / 'deep.txt').read_text() == 'deep'
    assert f'it is kept at {kept}' in ' '.join(error.value.__notes__)


def test_writable_location_check(tmp_path: Path) -> None:
    check_writable_location(tmp_path / 'new' / 'deeper', '--out')
    assert list(tmp_path.iterdir()) == []
    (tmp_path / 'file').write_text('x')
    with pytest.raises(InputError, match=r'--out .*file/sub: .*file is not a directory'):
        check_writable_location(tmp_path / 'file' / 'sub', '--out')
    # /proc refuses new entries even to root, unlike a chmod-ed directory.
    with pytest.raises(InputError, match='infinihand_out: cannot create anything in /proc'):
        check_writable_location('/proc/infinihand_out', '--out')
