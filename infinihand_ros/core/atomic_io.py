"""Atomic file and directory writes: a reader never sees a half-written output.

Outputs are written under a temporary name next to their final path and renamed into place only
when complete; on any error the temporary output is removed and what existed before is untouched.
"""

from collections.abc import Iterator
import contextlib
import logging
import os
from pathlib import Path
import shutil
import tempfile
from typing import Final

from infinihand_ros.core.errors import InputError

logger = logging.getLogger(__name__)

#: Suffix of the hidden sibling that holds the replaced output until the new one is in place.
_OLD_SUFFIX: Final = '.old'


@contextlib.contextmanager
def atomic_directory(final_path: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary directory path that becomes ``final_path`` when the block succeeds.

    The yielded path does not exist yet (tools like rosbags' Writer create it themselves). An
    existing ``final_path`` is replaced without ever being missing or half-written: the new
    output is written beside it, the old one is renamed to a hidden sibling, the new one is
    renamed in and only then is the old one deleted. If any step fails, the old output is put
    back and the error is raised.

    Args:
        final_path: the directory (or file) the block's output replaces.
        overwrite: replace an existing ``final_path``; False refuses it.

    Yields:
        The path to write, in the same directory as ``final_path`` (so the rename is atomic).

    Raises:
        InputError: if ``final_path`` exists and ``overwrite`` is False.

    """
    final_path = Path(final_path)
    if os.path.lexists(final_path) and not overwrite:
        raise InputError(f'{final_path} already exists; choose another path or remove it')
    final_path.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f'.{final_path.name}.', dir=final_path.parent))
    work = staging / final_path.name
    old = staging.with_name(staging.name + _OLD_SUFFIX)
    try:
        yield work
        _swap_in(work, final_path, old)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    _remove_quietly(old)


def _swap_in(work: Path, final_path: Path, old: Path) -> None:
    """Rename ``final_path`` (if any) to ``old`` and ``work`` to ``final_path``; undo on error."""
    had_old = os.path.lexists(final_path)
    if had_old:
        os.replace(final_path, old)
    try:
        os.replace(work, final_path)
    except BaseException as exc:
        if had_old:
            try:
                os.replace(old, final_path)
            except OSError as restore_error:
                exc.add_note(f'the previous {final_path} could not be put back '
                             f'({restore_error}); it is kept at {old}')
        raise


def _remove_quietly(path: Path) -> None:
    """Delete a replaced output; a failure only leaves a hidden sibling behind (logged)."""
    if not os.path.lexists(path):
        return
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()
    except OSError as exc:
        logger.warning('could not delete the replaced output %s: %s', path, exc)


def check_writable_location(path: str | Path, what: str) -> None:
    """Check that a file or directory can be created at ``path`` (nothing is left behind).

    The nearest existing ancestor of ``path`` (or ``path`` itself) must be a directory in which
    a directory can be created.

    Args:
        path: the output to be written.
        what: what the caller calls the output in messages (e.g. ``'--out'``).

    Raises:
        InputError: naming ``path`` and the ancestor that is not a directory or not writable.

    """
    path = Path(path)
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(f'{what} {path}: {existing} is not a directory; '
                         'choose a path inside a directory')
    try:
        Path(tempfile.mkdtemp(prefix='.write-check.', dir=existing)).rmdir()
    except OSError as exc:
        raise InputError(f'{what} {path}: cannot create anything in {existing} '
                         f'({exc.strerror or exc}); choose a writable directory') from exc


def _current_umask() -> int:
    """Return the process umask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def honour_umask(path: str | Path) -> None:
    """Give a file created private (safetensors writes 0600) the umask's usual permissions."""
    os.chmod(path, 0o666 & ~_current_umask())


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and an atomic rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temp_name = tempfile.mkstemp(prefix=f'.{path.name}.', dir=path.parent)
    try:
        os.fchmod(handle, 0o666 & ~_current_umask())  # mkstemp creates 0600; honour the umask
        with os.fdopen(handle, 'wb') as stream:
            stream.write(data)
        os.replace(temp_name, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temp_name)
        raise
