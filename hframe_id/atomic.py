"""Atomic file writes: a temporary file in the target's folder, then a rename.

A reader (or a crash) never sees half a file: either the old file or the complete new one.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def replace_atomically(path: str | os.PathLike, data: str | bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file and ``os.replace``.

    The new file gets the usual umask-based mode (``mkstemp`` would leave it 0600). On any
    failure the temporary file is removed and ``path`` is untouched.
    """
    path = Path(path)
    payload = data.encode() if isinstance(data, str) else data
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        umask = os.umask(0o022)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        with os.fdopen(fd, "wb") as handle:
            handle.write(payload)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
