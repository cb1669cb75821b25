"""Atomic file and directory writes: a reader never sees a half-written output.

Outputs are written under a temporary name next to their final path and renamed into place only
when complete; on any error the temporary output is removed and what existed before is untouched.
"""

from collections.abc import Iterator
import contextlib
import os
from pathlib import Path
import shutil
import tempfile

from infinihand_ros.core.errors import InputError


@contextlib.contextmanager
def atomic_directory(final_path: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary directory path that becomes ``final_path`` when the block succeeds.

    The yielded path does not exist yet (tools like rosbags' Writer create it themselves).

    Raises:
        InputError: if ``final_path`` exists and ``overwrite`` is False.

    """
    final_path = Path(final_path)
    if final_path.exists() and not overwrite:
        raise InputError(f'{final_path} already exists; choose another path or remove it')
    final_path.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f'.{final_path.name}.', dir=final_path.parent))
    work = staging / final_path.name
    try:
        yield work
        if final_path.exists():
            shutil.rmtree(final_path) if final_path.is_dir() else final_path.unlink()
        os.replace(work, final_path)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _current_umask() -> int:
    """Return the process umask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


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
