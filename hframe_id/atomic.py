"""Atomic file writes: a temporary file (or folder) in the target's folder, then a rename.

A reader (or a crash) never sees half a file: either the old file or the complete new one.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def _umask() -> int:
    umask = os.umask(0o022)
    os.umask(umask)
    return umask


def replace_atomically(path: str | os.PathLike, data: str | bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file and ``os.replace``.

    The new file gets the usual umask-based mode (``mkstemp`` would leave it 0600). On any
    failure the temporary file is removed and ``path`` is untouched.
    """
    path = Path(path)
    payload = data.encode() if isinstance(data, str) else data
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as handle:
            handle.write(payload)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


@contextmanager
def staged_directory(path: str | os.PathLike) -> Iterator[Path]:
    """A hidden temporary folder beside ``path`` to fill, renamed to ``path`` when the block
    ends normally and removed with its contents on any exception.

    ``path`` must not exist. The folder gets the usual umask-based mode (``mkdtemp`` would
    leave it 0700).
    """
    path = Path(path)
    staging = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    try:
        yield staging
        os.chmod(staging, 0o777 & ~_umask())
        os.rename(staging, path)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
