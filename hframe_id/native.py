"""Native code for CasADi functions: generate C, compile it, cache it on disk, load it.

The one place where hframe-id calls a C compiler. The simulators and the closed loop
(``simulation.compiled``), the k-step prediction and the fitter's window loop
(``fitting.kernel``) all build through ``compile_function`` or ``build``, so every compiled
function is found, keyed, cached and cleaned the same way.

Compiler: ``$CC`` if set, else ``cc``, else ``gcc``; each build runs under a timeout
(``COMPILE_TIMEOUT_S``). Flags: the caller's, plus ``-fPIC -shared``; ``native_flags`` (such
as ``-march=native``) are tried first and dropped if the compiler refuses them.

Cache: one folder, ``$HFRAME_ID_CACHE/native`` or ``$XDG_CACHE_HOME/hframe-id/native``
(default ``~/.cache/hframe-id/native``). A library is ``NAME-KEY.so``, KEY the hash of the C
source, the compiler (path and version), the flags, the CasADi version and the host CPU (what
``-march=native`` resolves from), so a changed input never loads a stale library. Libraries
are written atomically (concurrent processes never see half a file); when the folder grows
beyond ``MAX_CACHE_BYTES`` the least recently used are deleted, and ``hframe-id cache clear``
empties it. The cache heals itself: a cached library that does not load (cut short, emptied,
overwritten) is built again, once; if that one does not load either, CasADi evaluates (one
warning, as below). A cache folder that cannot be used (``$HFRAME_ID_CACHE`` names a file,
or a folder that cannot be made or written) costs one ``NativeCacheWarning`` line: the
libraries then go to a private folder of the process, removed when it exits.

A compile still running after two seconds is announced on the ``hframe_id.native`` logger,
which the command line shows as a progress line on stderr (not with ``--quiet``); Ctrl-C or
SIGTERM while the compiler runs kills its whole process group before the command ends.

Without a working compiler nothing fails: ``build`` and ``compile_function`` return None, and
the first such failure in a process is reported by one ``NativeCodeWarning`` line; callers
then evaluate with CasADi's own virtual machine (same results, slower).
"""

from __future__ import annotations

import atexit
import ctypes
import hashlib
import logging
import os
import platform
import shutil
import signal
import subprocess
import tempfile
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import casadi as ca

logger = logging.getLogger(__name__)

#: Seconds one compiler run may take before it counts as failed (the largest simulator, a
#: map over 10^5 samples, takes about 20 s on a loaded 2-core machine).
COMPILE_TIMEOUT_S = 600
#: Seconds the compiler's ``--version`` may take (it answers in milliseconds): a compiler
#: that hangs is then no compiler (CasADi evaluates), not a 600 s wait with nothing shown.
VERSION_TIMEOUT_S = 10
#: Cache size [bytes] beyond which the least recently used libraries are deleted.
MAX_CACHE_BYTES = 512 * 2**20
#: Flags every shared library needs.
LIBRARY_FLAGS = ("-fPIC", "-shared")
#: Seconds after which a compile still running is announced (``logger``, INFO): the largest
#: sources (570 kB of C, an hframe-20 fit's window loop) take 4-5 s on a loaded 2-core machine.
ANNOUNCE_AFTER_S = 2.0
#: Folders of the two caches this module replaced (``cache clear`` removes them too).
_LEGACY_FOLDERS = ("casadi", "kernels")


class NativeCodeWarning(RuntimeWarning):
    """Native code could not be built; CasADi's virtual machine evaluates instead (slower)."""


class NativeCacheWarning(RuntimeWarning):
    """The cache folder cannot be used; compiled code is kept for this process only."""


@dataclass(frozen=True)
class CacheInfo:
    """The cache folder, its number of libraries and its size [bytes]."""

    folder: Path
    libraries: int
    size: int


_warned = False
_private: Path | None = None  # this process's folder when the cache folder is unusable


@dataclass(frozen=True)
class NativeSettings:
    """Where compiled code is cached and which compilers are tried, in order."""

    cache_root: Path
    compilers: tuple[str, ...]


def settings() -> NativeSettings:
    """The user's settings for native code, read from the environment at each call.

    With ``hframe_id.models.user.load_timeout_s`` (``HFRAME_ID_LOAD_TIMEOUT``), this is one
    of the two functions below the command line that read environment variables, and it
    reads only these three on purpose:

    - ``CC`` (compiler; else ``cc``, else ``gcc``) and ``XDG_CACHE_HOME`` (cache base; else
      ``~/.cache``) are the platform's conventions, which every tool that compiles or caches
      reads where it does so (make, setuptools, pip, matplotlib);
    - ``HFRAME_ID_CACHE`` overrides the folder (``$HFRAME_ID_CACHE``, else
      ``$XDG_CACHE_HOME/hframe-id``) in the same way ``PIP_CACHE_DIR`` or ``MPLCONFIGDIR``
      do.

    Native code is built wherever a model is first evaluated: by the command line, by the
    Python API, in test processes and in Dask worker processes on other machines (which share
    the environment, not the objects, of the process that started them: docs/fleet.md). A
    settings object resolved once in the CLI would have to be passed through every simulator,
    the closed loop, the prediction and the fitter's kernel and would still miss library
    users and workers; reading at the point of use, in this one function, does not. Nothing
    is read at import, and nothing is kept between calls (a changed environment applies to
    the next build).
    """
    root = os.environ.get("HFRAME_ID_CACHE")
    if root:
        cache = Path(root)
    else:
        base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
        cache = Path(base) / "hframe-id"
    cc = os.environ.get("CC")
    return NativeSettings(cache_root=cache, compilers=(cc, "cc", "gcc") if cc else ("cc", "gcc"))


def cache_root() -> Path:
    """The hframe-id cache folder: ``$HFRAME_ID_CACHE`` or ``$XDG_CACHE_HOME/hframe-id``
    (:func:`settings`)."""
    return settings().cache_root


def cache_directory() -> Path:
    """Where compiled libraries live (``cache_root() / "native"``)."""
    return cache_root() / "native"


def _unusable(folder: Path) -> str | None:
    """Why ``folder`` cannot hold the cache (one line: it, or a folder above it, is a file;
    it cannot be made or written), or None if it can. Makes the folder."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as err:
        return f"{folder}: {err.strerror or err}"
    return None


def _library_folder() -> Path:
    """``cache_directory()``, or where it cannot be used (``$HFRAME_ID_CACHE`` names a file
    or a folder that cannot be written), a private folder of this process, removed when it
    exits, after one ``NativeCacheWarning``: native code still runs, built afresh in each
    process."""
    folder = cache_directory()
    reason = _unusable(folder)
    if reason is None:
        return folder
    global _private
    if _private is None:
        _private = Path(tempfile.mkdtemp(prefix="hframe-id-native-"))
        atexit.register(shutil.rmtree, _private, ignore_errors=True)
        warnings.warn_explicit(
            f"cache folder unusable ({reason}); compiled code is not kept after this run",
            NativeCacheWarning,
            "hframe-id",
            0,
            module="hframe_id.native",
        )
    return _private


@lru_cache(maxsize=4)
def _compiler_identity(name: str) -> tuple[str, str] | None:
    """(path, first line of ``--version``) of compiler ``name``, or None if it does not run."""
    path = shutil.which(name)
    if path is None:
        return None
    try:
        process = _start([path, "--version"])
        with _group_killed_on_error(process):
            stdout, _ = process.communicate(timeout=VERSION_TIMEOUT_S)
    except (OSError, subprocess.SubprocessError):
        return None
    if process.returncode != 0 or not stdout:
        return None
    return path, stdout.splitlines()[0]


def _start(command: Sequence[str]) -> subprocess.Popen:
    """Start ``command`` (a compiler) in a session of its own, its output piped as text."""
    return subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )


@contextmanager
def _group_killed_on_error(process: subprocess.Popen) -> Iterator[None]:
    """On any exception in the block (a timeout, Ctrl-C, SIGTERM), kill the whole process
    group of ``process`` (started by ``_start``: the driver and cc1, as, ld; or the script
    a ``$CC`` names and what it runs), not only its first process, whose children would
    otherwise run on; the terminal's Ctrl-C does not reach the group itself."""
    try:
        yield
    except BaseException:
        os.killpg(process.pid, signal.SIGKILL)
        process.communicate()
        raise


def compiler() -> tuple[str, str] | None:
    """(path, version) of the C compiler used (``$CC``, ``cc`` or ``gcc``: :func:`settings`),
    None if none runs."""
    for name in settings().compilers:
        identity = _compiler_identity(name)
        if identity is not None:
            return identity
    return None


def compiler_available() -> bool:
    """True if a C compiler runs here (so native code can be built)."""
    return compiler() is not None


@lru_cache(maxsize=1)
def _host() -> str:
    """What ``-march=native`` resolves from: the architecture and, on Linux, the CPU model
    and flags (a cache shared by different machines keeps one library per kind of CPU)."""
    host = f"{platform.machine()} {platform.processor()}"
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        return host
    for key in ("model name", "flags"):
        host += next((" " + line for line in lines if line.startswith(key)), "")
    return host


def cache_key(source: str, flags: Sequence[str], identity: tuple[str, str]) -> str:
    """The cache key of ``source`` built with ``flags`` by compiler ``identity`` (path,
    version): a hash that also covers the CasADi version and the host CPU."""
    parts = (source, " ".join(flags), *identity, ca.__version__, _host())
    return hashlib.sha256("\0".join(parts).encode()).hexdigest()[:24]


def c_source(function: ca.Function) -> str:
    """The C source of ``function`` (CasADi's code generator, no header)."""
    generator = ca.CodeGenerator(f"{function.name()}.c", {"with_header": False})
    generator.add(function)
    return generator.dump()


def _warn_once(reason: str) -> None:
    """One ``NativeCodeWarning`` line per process: later failures have the same consequence
    (CasADi's virtual machine) and would only repeat it."""
    global _warned
    if _warned:
        return
    _warned = True
    # warn_explicit without a source line: the warning prints as one line.
    warnings.warn_explicit(
        f"native code unavailable ({reason}); evaluating with CasADi's virtual machine",
        NativeCodeWarning,
        "hframe-id",
        0,
        module="hframe_id.native",
    )


def _wait(process: subprocess.Popen, library: Path, source_bytes: int) -> str:
    """The compiler's stderr once it has ended; a compile still running after
    ``ANNOUNCE_AFTER_S`` is announced (``logger``, INFO). ``TimeoutExpired`` after
    ``COMPILE_TIMEOUT_S``."""
    announce_after_s = min(ANNOUNCE_AFTER_S, COMPILE_TIMEOUT_S)
    try:
        return process.communicate(timeout=announce_after_s)[1]
    except subprocess.TimeoutExpired:
        if announce_after_s >= COMPILE_TIMEOUT_S:
            raise
    logger.info(
        "compiling %s (%d kB of C) to native code, once: it is kept in %s",
        library.name.rsplit("-", 1)[0],
        source_bytes // 1000,
        library.parent,
    )
    return process.communicate(timeout=COMPILE_TIMEOUT_S - announce_after_s)[1]


def _run_compiler(path: str, flags: Sequence[str], source: str, library: Path) -> str | None:
    """Compile ``source`` with ``flags`` into ``library`` (atomically); the reason as one
    line if the compiler fails or times out, else None.

    The compiler runs in a session of its own, killed as a group on a timeout, Ctrl-C or
    SIGTERM (``_group_killed_on_error``) before the exception goes on.
    """
    library.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=library.parent) as scratch:
        c_file = Path(scratch) / "source.c"
        c_file.write_text(source)
        built = Path(scratch) / library.name
        command = [path, *flags, *LIBRARY_FLAGS, str(c_file), "-o", str(built), "-lm"]
        try:
            process = _start(command)
        except OSError as err:
            return f"{Path(path).name}: {err}"
        try:
            with _group_killed_on_error(process):
                stderr = _wait(process, library, len(source))
        except subprocess.TimeoutExpired:
            return f"{Path(path).name} took more than {COMPILE_TIMEOUT_S} s"
        if process.returncode != 0:
            errors = [line for line in stderr.splitlines() if "error" in line]
            detail = (errors or stderr.splitlines() or ["no message"])[0]
            return f"{Path(path).name} failed: {detail.strip()}"
        os.replace(built, library)
    return None


def _loads(library: Path) -> bool:
    """True if ``library`` loads as a shared library (a file cut short, emptied or
    overwritten does not: it is then rebuilt)."""
    try:
        ctypes.CDLL(str(library))
    except OSError:
        return False
    return True


def _stat(path: Path) -> tuple[float, int]:
    """(last use, size [bytes]) of a cached library; (0, 0) if another process removed it."""
    try:
        status = path.stat()
    except FileNotFoundError:
        return 0.0, 0
    return status.st_mtime, status.st_size


def _prune(folder: Path, keep: Path) -> None:
    """Delete the least recently used libraries of ``folder`` while they exceed
    ``MAX_CACHE_BYTES`` (never ``keep``). A library loaded by a running process stays
    usable: it is unlinked, not overwritten."""
    libraries = sorted((*_stat(f), f) for f in folder.glob("*.so"))
    total = sum(size for _, size, _ in libraries)
    for _, size, library in libraries:
        if total <= MAX_CACHE_BYTES:
            break
        if library != keep:
            total -= size
            library.unlink(missing_ok=True)


def build(
    name: str, source: str, flags: Sequence[str] = (), native_flags: Sequence[str] = ()
) -> Path | None:
    """The shared library of C ``source``, built once and cached (see the module docstring).

    ``flags`` are always used; ``native_flags`` are tried first and dropped if that build
    fails. A cached library that does not load (cut short, emptied, overwritten) is deleted
    and built again, once. Returns the library's path, or None (after one
    ``NativeCodeWarning`` per process) if no compiler runs, it fails, or what it built does
    not load either.
    """
    identity = compiler()
    if identity is None:
        _warn_once("no C compiler: $CC, cc and gcc not found")
        return None
    folder = _library_folder()
    attempts = [(*flags, *native_flags), tuple(flags)] if native_flags else [tuple(flags)]
    reason = None
    for attempt in attempts:
        library = folder / f"{name}-{cache_key(source, attempt, identity)}.so"
        try:
            os.utime(library)  # recently used: the last to be pruned
        except FileNotFoundError:
            pass  # not built yet (or just pruned by another process)
        else:
            if _loads(library):
                return library
            library.unlink(missing_ok=True)  # damaged: built again below
        reason = _run_compiler(identity[0], attempt, source, library)
        if reason is None and not _loads(library):
            library.unlink(missing_ok=True)
            reason = "the library built does not load"
        if reason is None:
            _prune(folder, keep=library)
            return library
    _warn_once(f"{reason} on {name}")
    return None


def compile_function(
    function: ca.Function,
    flags: Sequence[str] = ("-O2",),
    native_flags: Sequence[str] = (),
    prelude: str = "",
) -> ca.Function | None:
    """``function`` as native code (same name, inputs and outputs), or None where it cannot
    be built or loaded (then evaluate ``function`` itself). ``prelude`` is C put before the
    generated source (inline replacements of math functions, say)."""
    library = build(function.name(), prelude + c_source(function), flags, native_flags)
    if library is None:
        return None
    try:
        return ca.external(function.name(), str(library))
    except RuntimeError as err:  # loads, but not as CasADi expects (no such function)
        _warn_once(f"{library.name} does not load into CasADi: {str(err).splitlines()[0]}")
        return None


def cache_info() -> CacheInfo:
    """The cache folder, the number of libraries in it and their size [bytes]."""
    folder = cache_directory()
    libraries = list(folder.glob("*.so")) if folder.is_dir() else []
    return CacheInfo(folder, len(libraries), sum(_stat(f)[1] for f in libraries))


def clear_cache() -> int:
    """Delete every cached library (and the folders of the caches this module replaced);
    returns the number of bytes freed. Running processes keep the libraries they loaded."""
    freed = 0
    for folder in (cache_directory(), *(cache_root() / old for old in _LEGACY_FOLDERS)):
        if not folder.is_dir():
            continue
        freed += sum(_stat(f)[1] for f in folder.rglob("*") if f.is_file())
        shutil.rmtree(folder, ignore_errors=True)
    return freed
