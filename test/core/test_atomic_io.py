"""Atomic writes: complete outputs or none, earlier outputs kept on failure, umask honoured."""

import os
from pathlib import Path

from infinihand_ros.core.atomic_io import atomic_directory
from infinihand_ros.core.atomic_io import atomic_write_bytes
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
