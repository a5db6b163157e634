"""Native code for the simulators: their compiler flags and inline tanh, and NumPy evaluation.

The simulators are CasADi SX graphs mapped over the horizon (``mapaccum``); CasADi's virtual
machine evaluates them at about 10 ns per operation, C compiled by gcc about 4x faster. The
build, the disk cache and the fallback without a compiler are ``hframe_id.native``'s; this
module adds the simulators' flags and inline tanh: the first call in a fresh cache costs one
compiler run (about 1-2 s), later calls and later processes none.

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

import casadi as ca
import numpy as np

from hframe_id import native

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

#: Compiler flags of the simulators; -march=native is tried first (``native.build``).
FLAGS = ("-O3", "-fno-math-errno", "-freciprocal-math")
NATIVE_FLAGS = ("-march=native",)


def compile_function(function: ca.Function) -> ca.Function | None:
    """``function`` as native code with the simulators' flags and inline tanh (same name,
    inputs, outputs), built once and cached on disk; None where it cannot be built."""
    return native.compile_function(function, FLAGS, NATIVE_FLAGS, prelude=TANH_PRELUDE)


def maybe_compile(function: ca.Function, compiled: bool) -> ca.Function:
    """``compile_function(function)`` if ``compiled``; ``function`` itself (CasADi's virtual
    machine) if not, or if native code cannot be built here (``native`` warns once)."""
    native_function = compile_function(function) if compiled else None
    return function if native_function is None else native_function


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
