"""Output paths and run lengths checked before any work is done.

A command that cannot write its result says so at once, as one line with exit status 2,
instead of failing after seconds or minutes of computing, and writes nothing. Writability is
probed by creating (and at once removing) a temporary file where the output would go: the
permission bits say little when running as root or on special file systems such as /proc.
A run longer than ``MAX_SAMPLES`` is refused the same way, before its tables are allocated.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from hframe_id.errors import OptionError


def _probe(directory: Path, option: str, target: Path) -> None:
    """Raise unless a file can be created in the existing ``directory``."""
    try:
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError as err:
        raise OptionError(
            f"{option} {target}: cannot write in {directory} ({err.strerror})"
        ) from None


def check_file(path: str | os.PathLike, option: str, make_parents: bool = False) -> Path:
    """Check that the file ``path`` (given with ``option``) can be written: not a folder, its
    folder exists (or, with ``make_parents``, its nearest existing ancestor is a folder) and
    accepts new files. Existing files are the command's business (``--overwrite``)."""
    path = Path(path)
    if path.is_dir():
        raise OptionError(f"{option} {path}: is a directory; give a file name")
    folder = path.parent
    if make_parents:
        while not folder.exists() and folder != folder.parent:
            folder = folder.parent
    if not folder.exists():
        raise OptionError(f"{option} {path}: folder {folder} does not exist")
    if not folder.is_dir():
        raise OptionError(f"{option} {path}: {folder} is not a directory")
    _probe(folder, option, path)
    return path


def check_dir(path: str | os.PathLike, option: str) -> Path:
    """Check that the folder ``path`` (given with ``option``) exists or can be created, and
    accepts new files; creates nothing."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OptionError(f"{option} {path}: exists and is not a directory")
    ancestor = path
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise OptionError(f"{option} {path}: {ancestor} is not a directory")
    _probe(ancestor, option, path)
    return path


#: Samples one simulated or recorded run may have: 10 million is 2.8 h at 1 kHz and keeps the
#: signal tables near a gigabyte; longer runs fail at once instead of with a MemoryError.
MAX_SAMPLES = 10_000_000


def check_length(duration_s: float, period_s: float, option: str) -> None:
    """Refuse a run of more than MAX_SAMPLES samples of ``period_s`` (``option`` names the
    setting at fault)."""
    samples = duration_s / period_s
    if samples > MAX_SAMPLES:
        raise OptionError(
            f"{option}: {duration_s:g} s at {period_s * 1e3:g} ms is {samples:.3g} samples; "
            f"at most {MAX_SAMPLES:,} per run ({MAX_SAMPLES * period_s / 3600:.3g} h)"
        )
