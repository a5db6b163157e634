"""Compile CasADi functions to native code once, and reuse them across processes.

The simulators are CasADi SX graphs mapped over the horizon (``mapaccum``); CasADi's virtual
machine evaluates them at about 10 ns per operation, C compiled by gcc about 4x faster. The C
source of a function is deterministic, so the shared library is cached on disk under the hash of
(source, compiler flags, compiler version, CPU) and loaded with ``casadi.external``: the first
call in a fresh cache costs one gcc run (about 1-2 s), later calls and later processes none.

No ``-ffast-math``: gcc links crtfastmath.o into shared libraries, which would switch the whole
Python process to flush-denormals-to-zero on load.
"""

from __future__ import annotations

import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import warnings
from functools import lru_cache
from pathlib import Path

import casadi as ca

#: gcc flags for the simulators (-march=native is safe: the CPU is part of the cache key).
FLAGS = ("-O3", "-march=native", "-fno-math-errno", "-fPIC", "-shared")


def cache_directory() -> Path:
    """Where compiled simulators live: ``$HFRAME_ID_CACHE`` or ``~/.cache/hframe-id/casadi``."""
    root = os.environ.get("HFRAME_ID_CACHE")
    if root:
        return Path(root) / "casadi"
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "hframe-id" / "casadi"


@lru_cache(maxsize=1)
def _machine_key() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith(("model name", "flags")):
                cpu += line
    except OSError:
        pass
    return cpu


@lru_cache(maxsize=4)
def _compiler_version(compiler: str) -> str | None:
    path = shutil.which(compiler)
    if path is None:
        return None
    try:
        result = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return result.stdout.splitlines()[0] if result.returncode == 0 and result.stdout else None


def compiler_available(compiler: str = "gcc") -> bool:
    """True if ``compiler`` runs (so ``compile_function`` can build native code)."""
    return _compiler_version(compiler) is not None


def compile_function(function: ca.Function, compiler: str = "gcc") -> ca.Function:
    """``function`` as native code (same name, inputs, outputs), built once and cached on disk.

    Raises ``RuntimeError`` if the compiler is missing or fails.
    """
    version = _compiler_version(compiler)
    if version is None:
        raise RuntimeError(f"C compiler {compiler!r} not found")
    generator = ca.CodeGenerator(f"{function.name()}.c", {"with_header": False})
    generator.add(function)
    source = generator.dump()
    key = hashlib.sha256(
        "\0".join((source, " ".join(FLAGS), version, _machine_key())).encode()
    ).hexdigest()[:24]
    directory = cache_directory()
    library = directory / f"{function.name()}-{key}.so"
    if not library.exists():
        directory.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=directory) as scratch:
            c_file = Path(scratch) / f"{function.name()}.c"
            c_file.write_text(source)
            built = Path(scratch) / library.name
            result = subprocess.run(
                [compiler, *FLAGS, str(c_file), "-o", str(built), "-lm"],
                capture_output=True,
                text=True,
                timeout=600,
            )
            if result.returncode != 0:
                raise RuntimeError(
                    f"{compiler} failed on {function.name()}: {result.stderr[-500:]}"
                )
            os.replace(built, library)  # atomic: concurrent processes never see half a library
    return ca.external(function.name(), str(library))


def maybe_compile(function: ca.Function, compiled: bool) -> ca.Function:
    """``compile_function(function)`` if ``compiled``, falling back (with a warning) to the VM."""
    if not compiled:
        return function
    try:
        return compile_function(function)
    except (RuntimeError, OSError) as err:
        warnings.warn(
            f"native compilation unavailable ({err}); using CasADi's virtual machine",
            RuntimeWarning,
            stacklevel=2,
        )
        return function
