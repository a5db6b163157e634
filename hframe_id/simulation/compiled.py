"""Compile CasADi functions to native code once, and reuse them across processes.

The simulators are CasADi SX graphs mapped over the horizon (``mapaccum``); CasADi's virtual
machine evaluates them at about 10 ns per operation, C compiled by gcc about 4x faster. The C
source of a function is deterministic, so the shared library is cached on disk under the hash of
(source, compiler flags, compiler version, CPU) and loaded with ``casadi.external``: the first
call in a fresh cache costs one gcc run (about 1-2 s), later calls and later processes none.

No ``-ffast-math``: gcc links crtfastmath.o into shared libraries, which would switch the whole
Python process to flush-denormals-to-zero on load. Only ``-freciprocal-math`` of it: divisions by
parameters (masses, inertias) become multiplications by reciprocals computed once, 25 % faster,
results within about 1e-12 of the virtual machine's.

``tanh`` is replaced by an inline version (``TANH_PRELUDE``): the smoothed Coulomb law calls it
four times per dynamics evaluation, 400 times per 1 ms sample of hframe-8, and glibc's ``tanh``
is an opaque call that costs about 60 % of the simulation. The inline version (odd Taylor series
below 0.25, (1 - e) / (1 + e) with e = exp(-2|x|) by range reduction and a degree-13 polynomial
above) is accurate to a few ulp (tested against NumPy) and lets gcc interleave independent
evaluations.
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
import numpy as np

#: Inline tanh for the generated code (see the module docstring); NaN propagates, +/-inf -> +/-1.
TANH_PRELUDE = r"""
#include <math.h>
#include <stdint.h>
#include <string.h>
static inline double hframe_exp_nonpositive(double y) {
  /* exp(y), -40 <= y <= 0: y = k ln2 + r, |r| <= ln2 / 2, exp(r) to degree 13 (< 1e-17). */
  const double ln2_hi = 6.93147180369123816490e-01, ln2_lo = 1.90821492927058770002e-10;
  double k = floor(y * 1.44269504088896338700e+00 + 0.5);
  double r = (y - k * ln2_hi) - k * ln2_lo;
  double p = 1.0/6227020800.0;
  p = p * r + 1.0/479001600.0; p = p * r + 1.0/39916800.0; p = p * r + 1.0/3628800.0;
  p = p * r + 1.0/362880.0; p = p * r + 1.0/40320.0; p = p * r + 1.0/5040.0;
  p = p * r + 1.0/720.0; p = p * r + 1.0/120.0; p = p * r + 1.0/24.0; p = p * r + 1.0/6.0;
  p = p * r + 0.5; p = p * r + 1.0; p = p * r + 1.0;
  uint64_t bits = (uint64_t)((int64_t)k + 1023) << 52;
  double scale;
  memcpy(&scale, &bits, sizeof scale);
  return p * scale;
}
static inline double hframe_tanh(double x) {
  double a = fabs(x), t;
  if (a < 0.25) {
    /* odd Taylor series to x^21; the next term is below 1e-18 relative */
    double a2 = a * a, q = 18888466084.0/194896477400625.0;
    q = q * a2 - 443861162.0/1856156927625.0; q = q * a2 + 6404582.0/10854718875.0;
    q = q * a2 - 929569.0/638512875.0; q = q * a2 + 21844.0/6081075.0;
    q = q * a2 - 1382.0/155925.0; q = q * a2 + 62.0/2835.0; q = q * a2 - 17.0/315.0;
    q = q * a2 + 2.0/15.0; q = q * a2 - 1.0/3.0;
    t = a + a * a2 * q;
  } else if (a < 19.0625) {
    double e = hframe_exp_nonpositive(-2.0 * a);
    t = (1.0 - e) / (1.0 + e);
  } else if (a == a) {
    t = 1.0;
  } else {
    return x;
  }
  return copysign(t, x);
}
#define tanh(x) hframe_tanh(x)
"""

#: gcc flags for the simulators (-march=native is safe: the CPU is part of the cache key).
FLAGS = ("-O3", "-march=native", "-fno-math-errno", "-freciprocal-math", "-fPIC", "-shared")


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
    if "tanh(" in source:
        source = TANH_PRELUDE + source
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


def evaluate(function: ca.Function, inputs: list[np.ndarray]) -> list[np.ndarray]:
    """Call ``function`` on NumPy arrays without DM conversions (``Function.buffer``).

    CasADi stores matrices column by column, so an (n x m) input is passed as an (m, n)
    C-ordered array (one row per column) and an (n x m) output comes back as (m, n). Avoids
    about 0.3 ms of conversion per 10^4 numbers, which matters for millisecond simulations.
    """
    buffer, run = function.buffer()
    arrays = [np.ascontiguousarray(value, dtype=float) for value in inputs]
    for i, array in enumerate(arrays):
        if array.size != function.nnz_in(i):
            raise ValueError(
                f"{function.name()} input {function.name_in(i)} needs {function.nnz_in(i)} "
                f"numbers, got {array.size}"
            )
        buffer.set_arg(i, memoryview(array))
    outputs = [
        np.empty((function.size2_out(i), function.size1_out(i))) for i in range(function.n_out())
    ]
    for i, array in enumerate(outputs):
        buffer.set_res(i, memoryview(array))
    run()
    return outputs
