"""Atomic file writes: a temporary file (or folder) in the target's folder, then a rename.

A reader (or a crash) never sees half a file: either the old file or the complete new one.
``replace_atomically`` writes one file; ``Staging`` holds the several outputs of one command
and puts them in place together once every one is complete; ``staged_directory`` is a
``Staging`` of one folder.
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


def _exists(path: Path) -> bool:
    return path.exists() or path.is_symlink()


class Staging:
    """The outputs of one command, written under hidden temporary names beside their targets
    and put in place together.

    ``file`` and ``folder`` give the temporary to write into (a file keeps its target's
    suffix, which matplotlib and pandas go by); ``commit`` renames every temporary onto its
    target once all are written, ``discard`` removes them and the folders made for them. A
    staged folder replaces its target as a whole. The temporaries get the usual umask-based
    modes (``mkstemp`` and ``mkdtemp`` would leave them 0600 and 0700).
    """

    def __init__(self) -> None:
        self._staged: list[tuple[Path, Path]] = []  # (temporary, target), in staging order
        self._made: list[Path] = []  # folders made for the targets, outermost first

    def file(self, target: str | os.PathLike) -> Path:
        """An empty temporary file to write ``target``'s content into."""
        target = Path(target)
        self._make_folder(target.parent)
        fd, name = tempfile.mkstemp(
            prefix=f".{target.stem}.", suffix=f".tmp{target.suffix}", dir=target.parent
        )
        os.close(fd)
        os.chmod(name, 0o666 & ~_umask())
        self._staged.append((Path(name), target))
        return Path(name)

    def write(self, target: str | os.PathLike, data: str | bytes) -> Path:
        """Stage ``data`` as ``target``'s content; returns ``target``."""
        payload = data.encode() if isinstance(data, str) else data
        self.file(target).write_bytes(payload)
        return Path(target)

    def folder(self, target: str | os.PathLike) -> Path:
        """An empty temporary folder to fill; it replaces the folder ``target`` as a whole."""
        target = Path(target)
        self._make_folder(target.parent)
        name = tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
        os.chmod(name, 0o777 & ~_umask())
        self._staged.append((Path(name), target))
        return Path(name)

    def target_of(self, path: Path) -> Path:
        """The target a staged temporary (or a path inside a staged folder) stands for;
        any other ``path`` as it is."""
        for tmp, target in self._staged:
            if path == tmp or tmp in path.parents:
                return target / path.relative_to(tmp)
        return path

    def _make_folder(self, folder: Path) -> None:
        missing = []
        while not folder.exists() and folder != folder.parent:
            missing.append(folder)
            folder = folder.parent
        for made in reversed(missing):
            made.mkdir()
            self._made.append(made)

    def commit(self) -> None:
        """Put every staged output in place, or none: a target that exists is first moved
        into a hidden folder beside it, and if any rename fails (the file system changed
        under the command) the outputs already placed are taken back (staged again, for
        ``discard``), the moved targets restored, and the ``OSError`` raised."""
        placed: list[tuple[Path, Path, Path | None]] = []  # (temporary, target, holder)
        try:
            for tmp, target in self._staged:
                holder = None
                if _exists(target):
                    holder = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
                placed.append((tmp, target, holder))
                if holder is not None:
                    os.replace(target, holder / target.name)
                os.replace(tmp, target)
        except BaseException:
            for tmp, target, holder in reversed(placed):
                if not _exists(tmp) and _exists(target):
                    os.replace(target, tmp)  # the new output, staged again
                if holder is not None:
                    if _exists(holder / target.name):
                        os.replace(holder / target.name, target)
                    shutil.rmtree(holder, ignore_errors=True)
            raise
        for _, _, holder in placed:
            if holder is not None:
                shutil.rmtree(holder, ignore_errors=True)
        self._staged.clear()
        self._made.clear()

    def discard(self) -> None:
        """Remove every output not yet in place, and the folders made for them if empty."""
        for tmp, _ in self._staged:
            if tmp.is_dir():
                shutil.rmtree(tmp, ignore_errors=True)
            else:
                tmp.unlink(missing_ok=True)
        self._staged.clear()
        for folder in reversed(self._made):
            try:
                folder.rmdir()
            except OSError:
                pass  # holds something else now (an output already put in place)
        self._made.clear()


@contextmanager
def staged_directory(path: str | os.PathLike) -> Iterator[Path]:
    """A hidden temporary folder beside ``path`` to fill, put in place as ``path`` (replacing
    it as a whole) when the block ends normally and removed with its contents on any
    exception."""
    staging = Staging()
    try:
        yield staging.folder(path)
        staging.commit()
    except BaseException:
        staging.discard()
        raise
