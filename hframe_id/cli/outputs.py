"""The output guard: every file and folder a command writes, checked before any work is done,
then written together.

A command that cannot write its result says so at once, as one line with exit status 2,
instead of failing after seconds or minutes of computing, and writes nothing. The guard
checks, for each output: that it is of the right kind (a file where a file goes, a folder
where a folder goes), that it does not exist unless ``--force`` is given, that its folder
exists (or can be made), can be reached (every folder on the way searchable) and that new files
can be created there, and that an existing file or folder it replaces (given ``--force``) is not
read-only.
Writability is probed by creating (and at once removing) a temporary file where the output
would go: the permission bits say little when running as root or on special file systems
such as /proc.

Within one command (``command``) the guard also refuses an existing file that the command
line names twice, once as an input (``reduce F.yaml --out F.yaml --force`` replaced the
parameter file it read), and two outputs on one path (``control --csv p --plot p`` failed
after the simulation), even with ``--force``.

The outputs are then written through ``written_together``: each under a hidden temporary name
beside its target, all put in place when the command's work is done, none on any failure.
A run longer than ``MAX_SAMPLES`` is refused the same way, before its tables are allocated.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from hframe_id.atomic import Staging
from hframe_id.cli import signals
from hframe_id.errors import OptionError, shown


def add_force_option(parser: argparse.ArgumentParser, *aliases: str) -> None:
    """``--force`` (and ``aliases``, kept for old scripts): replace existing outputs."""
    parser.add_argument(
        "--force",
        *aliases,
        dest="force",
        action="store_true",
        help="replace output files that exist already (default: refuse, before any work)",
    )


@dataclass
class _Command:
    """The command the guard checks outputs for: the words of its command line and the
    outputs checked so far (absolute path: option, whether a folder)."""

    words: tuple[str, ...]
    claimed: dict[str, tuple[str, bool]] = field(default_factory=dict)


_running: _Command | None = None


@contextmanager
def command(argv: Sequence[str]) -> Iterator[None]:
    """The outputs checked in the block belong to one command whose command line is
    ``argv``: an output that ``argv`` also names as an input, or that another of its outputs
    is written on (or under), is refused (``_claim``). Outside the block neither is checked."""
    global _running
    _running = _Command(tuple(str(word) for word in argv))
    try:
        yield
    finally:
        _running = None


def _named_files(words: Iterable[str]) -> Iterator[str]:
    """The paths a command line may name: each word, and the value of each ``--option=value``."""
    for word in words:
        yield word
        if word.startswith("--") and "=" in word:
            yield word.split("=", 1)[1]


def _refuse_input(path: Path, option: str) -> None:
    """Raise if the existing file ``path`` is named on the command line more than once: its
    output option names it once, so it is also one of the command's inputs."""
    if _running is None or not path.is_file():
        return
    named = 0
    for word in _named_files(_running.words):
        try:
            named += word != "" and os.path.samefile(word, path)
        except OSError:  # not a path, or nothing there
            continue
    if named > 1:
        raise OptionError(
            f"{option} {path}: is also an input of this command; write the output elsewhere"
        )


def _claim(path: Path, option: str, folder: bool) -> None:
    """Record ``path`` as an output of ``option``; raise if an output of another option is
    the same file, or a file that one of them would be written under."""
    if _running is None:
        return
    key = os.path.abspath(path)
    for other, (other_option, other_folder) in _running.claimed.items():
        if other_option == option:
            continue
        same = other == key and not (folder and other_folder)
        under_file = (key.startswith(other + os.sep) and not other_folder) or (
            other.startswith(key + os.sep) and not folder
        )
        if same or under_file:
            raise OptionError(
                f"{option} {path}: {other_option} {shown(other)} is written there too; give "
                "each output its own path"
            )
    _running.claimed.setdefault(key, (option, folder))


def _probe(directory: Path, option: str, target: Path) -> None:
    """Raise unless a file can be created in the existing ``directory``."""
    try:
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError as err:
        raise OptionError(
            f"{option} {target}: cannot write in {directory} ({err.strerror})"
        ) from None


def _reachable(path: Path, option: str, target: Path) -> None:
    """Raise unless every existing folder on the way to ``path`` can be searched: ``stat``
    of a name in a folder without execute permission (or an unreadable one, mode 000) fails
    with EACCES, which ``Path.exists`` passes on as a PermissionError."""
    for step in reversed((path, *path.parents)):
        try:
            os.lstat(step)
        except PermissionError as err:
            raise OptionError(
                f"{option} {target}: cannot reach it, folder {step.parent} cannot be "
                f"searched ({err.strerror})"
            ) from None
        except OSError:
            return  # missing, or under a file: the kind checks say which


def _nearest_folder(path: Path, option: str, target: Path) -> Path:
    """The nearest existing ancestor of ``path``, which must be a folder."""
    folder = path
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise OptionError(f"{option} {target}: {folder} is not a directory")
    return folder


def _check_target(
    path: Path, option: str, force: bool, folder: bool, replaced: bool = True
) -> None:
    """``path`` is of the kind it will be written as, and new unless ``force``. An output
    is put in place by a rename, which would replace a device, a pipe or a socket (as root,
    ``--out /dev/null --force`` would delete the system's /dev/null): those are refused even
    with ``--force``. So is a read-only file or folder that the output ``replaced`` as a
    whole: the rename would replace a file (its folder being writable), which its owner made
    it read-only to prevent; a folder is first moved aside (``Staging.commit``), a rename
    that needs write permission on the folder itself (its ``..`` entry), and would fail
    after the command's work. Root may write anything, and ``os.access`` says so. A folder
    written into (``replaced`` False) is checked by ``_probe``."""
    _reachable(path, option, path)
    _claim(path, option, folder)
    if folder and path.exists() and not path.is_dir():
        raise OptionError(f"{option} {path}: exists and is not a directory")
    if not folder and path.is_dir():
        raise OptionError(f"{option} {path}: is a directory, not a file")
    if not folder and path.exists() and not path.is_file():
        raise OptionError(
            f"{option} {path}: is a device, pipe or socket, not a file; give a file's path"
        )
    if (path.exists() or path.is_symlink()) and not force:
        raise OptionError(f"{option} {path}: exists already; pass --force to replace it")
    _refuse_input(path, option)
    if replaced and (path.is_file() or path.is_dir()) and not os.access(path, os.W_OK):
        raise OptionError(
            f"{option} {path}: exists and is read-only; make it writable or remove it first"
        )


def _file_name(text: str, option: str) -> Path:
    """``text`` as the path of a file: not empty and not ending with a separator (which
    ``Path`` would drop, writing a file where the user meant a folder)."""
    if not text or text.endswith(os.sep):
        raise OptionError(f"{option} {shown(text)}: a file's path is needed")
    return Path(text)


def output_file(option: str, suffix: str | None = None) -> Callable[[str], Path]:
    """An argparse ``type=`` for an output file's option: its path, checked as
    ``_file_name`` and, given a ``suffix`` (``.mcap``), named with it: ``record --out
    run.csv`` wrote a recording that ``--csv run.csv`` then failed to read (the rest of the
    guard, ``check_file``, runs before the command's work)."""

    def parse(text: str) -> Path:
        path = _file_name(text, option)
        if suffix is not None and path.suffix.lower() != suffix:
            raise OptionError(f"{option} needs a {suffix} file name, got {shown(text)}")
        return path

    return parse


def output_folder(option: str) -> Callable[[str], Path]:
    """An argparse ``type=`` for an output folder's option: its path, not empty (``--plot
    ''`` made validate draw nothing without a word, fleet report and datasets make use their
    default folder, and fleet make fail after its work); the rest of the guard,
    ``check_dir``, runs before the command's work."""

    def parse(text: str) -> Path:
        if not text.strip():
            raise OptionError(f"{option} {shown(text)}: a folder's path is needed")
        return Path(text)

    return parse


def check_file(
    path: str | os.PathLike, option: str, force: bool = False, make_parents: bool = False
) -> Path:
    """Check that the file ``path`` (given with ``option``) can be written: not a folder, new
    unless ``force``, its folder exists (or, with ``make_parents``, its nearest existing
    ancestor is a folder) and accepts new files."""
    path = _file_name(os.fspath(path), option)
    _check_target(path, option, force, folder=False)
    if not make_parents and not path.parent.exists():
        raise OptionError(f"{option} {path}: folder {path.parent} does not exist")
    _probe(_nearest_folder(path.parent, option, path), option, path)
    return path


def check_dir(
    path: str | os.PathLike,
    option: str,
    files: Iterable[str] = (),
    folders: Iterable[str] = (),
    force: bool = False,
    empty: bool = False,
) -> Path:
    """Check that the folder ``path`` (given with ``option``) exists or can be created and
    accepts new files, and that the ``files`` and ``folders`` the command writes into it
    (names relative to it; a folder is replaced as a whole) are of that kind and new unless
    ``force``. With ``empty`` the folder is the output, filled as a whole: it must not exist
    or be empty. Creates nothing."""
    path = Path(path)
    if empty and path.name in ("", ".", ".."):  # a rename cannot replace "." or "/"
        raise OptionError(f"{option} {path}: name the new folder, not . or .. or /")
    _check_target(path, option, force=True, folder=True, replaced=empty)
    if empty and path.is_dir():
        try:
            filled = any(path.iterdir())
        except OSError as err:
            raise OptionError(f"{option} {path}: cannot list it ({err.strerror})") from None
        if filled:
            raise OptionError(f"{option} {path}: exists and is not empty")
    for name in files:
        _check_target(path / name, option, force, folder=False)
    for name in folders:
        _check_target(path / name, option, force, folder=True)
    _probe(_nearest_folder(path, option, path), option, path)
    return path


@contextmanager
def written_together() -> Iterator[Staging]:
    """A ``Staging`` for the outputs written in the block: put in place together when the
    block ends normally (and no Ctrl-C or SIGTERM came meanwhile: ``signals.check``), removed
    on any exception. An ``OSError`` while writing or placing
    them (a full disk, a folder changed meanwhile) is an ``OptionError`` naming the output."""
    staging = Staging()
    try:
        with signals.discard_on_exit(staging.discard):
            yield staging
        signals.check()  # an interrupt lost in C code: nothing is put in place
        staging.commit()
    except OSError as err:
        where = staging.target_of(Path(err.filename)) if err.filename else "the outputs"
        staging.discard()
        raise OptionError(
            f"cannot write {where} ({err.strerror or err}); nothing written"
        ) from None
    except BaseException:
        staging.discard()
        raise


#: Samples one simulated or recorded run may have: 10 million is 2.8 h at 1 kHz and keeps the
#: signal tables near a gigabyte; longer runs fail at once instead of with a MemoryError.
MAX_SAMPLES = 10_000_000


def check_input(path: str | os.PathLike) -> Path:
    """``path`` as given, refused at once if the file cannot be opened for reading (mode
    000, or in a folder that cannot be searched): the readers would otherwise report the
    permission error without saying what failed. A missing file or a folder is left to the
    reader, whose message says what it expected there."""
    path = Path(path)
    try:
        with open(path, "rb"):
            pass
    except PermissionError as err:
        raise OptionError(f"{path}: cannot read ({err.strerror})") from None
    except OSError:
        pass
    return path


def check_distinct(paths: Iterable[str | os.PathLike], what: str) -> None:
    """Refuse a file given twice among ``paths`` (by name or through a link): ``fit R R``
    fitted one recording twice, doubling its weight and cross-validating it against itself."""
    seen: list[Path] = []
    for path in map(Path, paths):
        for earlier in seen:
            try:
                same = os.path.samefile(earlier, path)
            except OSError:  # missing: the reader says so
                same = False
            if same:
                raise OptionError(f"{what} {path}: given twice (also as {earlier})")
        seen.append(path)


def check_length(duration_s: float, period_s: float, option: str) -> None:
    """Refuse a run of more than MAX_SAMPLES samples of ``period_s`` (``option`` names the
    setting at fault)."""
    samples = duration_s / period_s
    if samples > MAX_SAMPLES:
        raise OptionError(
            f"{option}: {duration_s:g} s at {period_s * 1e3:g} ms is {samples:.3g} samples; "
            f"at most {MAX_SAMPLES:,} per run ({MAX_SAMPLES * period_s / 3600:.3g} h)"
        )
