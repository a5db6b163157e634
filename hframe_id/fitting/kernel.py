"""The compiled inner loop of the fitter: one RK4 substep with its exact sensitivities.

Multiple shooting needs, for every sample of every shooting window, the state and its
derivatives with respect to the window's initial state and the free parameters. They are
propagated alongside the state, substep by substep (exact derivatives of the discrete RK4 map,
so the Gauss-Newton Jacobian is the Jacobian of the residuals actually computed):

    x+ = Phi(x, u, p, s, h),    S+ = dPhi/dx S + [0, dPhi/dp_free]

with S = d x / d(x_0, p_free). Phi is ``hframe_id.simulation.integrators.rk4_substep``, the
simulators' RK4 step, with the substep length h a symbol (so the fitter's states are bitwise
the simulator's: tests/simulation/test_simulation_integrator.py). The substep is an SX graph
(~10^4 flat instructions), generated as C and compiled once per (model, free set) by
``hframe_id.native`` (cached on disk, so later fits load it in milliseconds). Where no C
compiler is available, CasADi's SX virtual machine runs the same graph about 2x slower.

Samples, windows and experiments are then layered on top: a C loop compiled with the substep
(``DRIVER``: windows split over threads, samples and substeps in sequence), or, without a C
compiler, MX ``mapaccum``/``map`` calls of this one function. Nothing is unrolled over the
record (the naive unrolled graph of a six-file fit does not fit in 24 GB).
"""

from __future__ import annotations

import ctypes
from functools import lru_cache
from pathlib import Path

import casadi as ca

from hframe_id import native
from hframe_id.models import Model
from hframe_id.simulation.integrators import rk4_substep

#: Compiler flags of the kernels: no value-changing optimization, so the results are bitwise
#: those of CasADi's virtual machine (tests/test_native.py).
COMPILE_FLAGS = ("-O2",)
#: Tried first: code for this machine's instruction set. VEX-encoded (AVX) code runs the
#: kernel 22 % faster on a Xeon with AVX-512 (an all-window evaluation through CasADi's
#: map 0.161 -> 0.124 s, already with -mavx alone); contraction into FMAs stays off, so the
#: results are bitwise those of the portable build.
NATIVE_FLAGS = ("-march=native", "-ffp-contract=off")

#: The loop over windows, samples and substeps, compiled with the substep: as the MX
#: map/mapaccum of ``window_function`` (the same calls on the same numbers, so bitwise the
#: same results) without its per-call overhead, padding or per-size construction.
#: Placeholders: FN (the substep), NX, ND (sensitivity columns, 0: none), NU.
DRIVER = r"""
#include <pthread.h>

typedef struct {
  const casadi_real *x0, *u, *p, *s;
  casadi_real h;
  int n_sub, m, first, last, status;
  casadi_real *xs, *ss;
} hf_job;

static void* hf_run(void* arg) {
  hf_job* job = (hf_job*)arg;
  casadi_real x[2][NX], sens[2][NX * ND + 1];
  const casadi_real* in[6];
  casadi_real* out[2];
  for (int w = job->first; w < job->last; ++w) {
    int c = 0;
    for (int i = 0; i < NX; ++i) x[0][i] = job->x0[w * NX + i];
    for (int i = 0; i < NX * ND; ++i) sens[0][i] = 0;
    for (int i = 0; i < NX && ND; ++i) sens[0][i * NX + i] = 1;
    for (int k = 0; k < job->m; ++k) {
      const casadi_real* u = job->u + (w * job->m + k) * NU;
      for (int j = 0; j < job->n_sub; ++j) {
        int a = 0;
        in[a++] = x[c];
        if (ND) in[a++] = sens[c];
        in[a++] = u;
        in[a++] = job->p;
        in[a++] = job->s;
        in[a++] = &job->h;
        out[0] = x[1 - c];
        out[1] = sens[1 - c];
        if (FN(in, out, 0, 0, 0)) {
          job->status = 1;
          return 0;
        }
        c = 1 - c;
      }
      long row = (long)w * job->m + k;
      for (int i = 0; i < NX; ++i) job->xs[row * NX + i] = x[c][i];
      for (int i = 0; i < NX * ND; ++i) job->ss[row * NX * ND + i] = sens[c][i];
    }
  }
  return 0;
}

CASADI_SYMBOL_EXPORT int hf_windows(const casadi_real* x0, const casadi_real* u,
    const casadi_real* p, const casadi_real* s, casadi_real h, int n_sub, int m,
    int n_windows, int n_threads, casadi_real* xs, casadi_real* ss) {
  hf_job jobs[64];
  pthread_t threads[64];
  if (n_threads < 1) n_threads = 1;
  if (n_threads > 64) n_threads = 64;
  if (n_threads > n_windows) n_threads = n_windows > 0 ? n_windows : 1;
  for (int t = 0; t < n_threads; ++t) {
    hf_job job = {x0, u, p, s, h, n_sub, m, (int)((long)n_windows * t / n_threads),
                  (int)((long)n_windows * (t + 1) / n_threads), 0, xs, ss};
    jobs[t] = job;
  }
  int started = 0;
  for (int t = 1; t < n_threads; ++t) {
    if (pthread_create(&threads[t], 0, hf_run, &jobs[t]) != 0) break;
    started = t;
  }
  for (int t = started + 1; t < n_threads; ++t) hf_run(&jobs[t]);  /* not started: here */
  hf_run(&jobs[0]);
  int status = jobs[0].status;
  for (int t = 1; t <= started; ++t) {
    pthread_join(threads[t], 0);
  }
  for (int t = 1; t < n_threads; ++t) status |= jobs[t].status;
  return status;
}
"""


def _rk4_symbols(model: Model) -> tuple[ca.SX, ...]:
    """Symbols (x, u, p, s, h) of one substep: state, held input, parameters, smoothing
    velocities [m/s, rad/s] and substep length [s] (an input, so one compiled kernel serves
    every substep count)."""
    return (
        ca.SX.sym("x", model.n_states),
        ca.SX.sym("u", model.n_inputs),
        ca.SX.sym("p", len(model.parameters)),
        ca.SX.sym("s", 2),
        ca.SX.sym("h"),
    )


def substep_function(model: Model, free: tuple[int, ...]) -> ca.Function:
    """SX function (x, S, u, p, s, h) -> (x_next, S_next) of one RK4 substep of length h.

    ``free`` are the indices (in ``model.parameters``) of the parameters whose sensitivities
    are carried; S has n_x + len(free) columns.
    """
    nx = model.n_states
    x, u, p, s, h = _rk4_symbols(model)
    sens = ca.SX.sym("S", nx, nx + len(free))
    x_next = rk4_substep(model.dynamics, x, u, p, s, h)
    phi_x = ca.jacobian(x_next, x)
    phi_p = ca.jacobian(x_next, p)[:, list(free)] if free else ca.SX(nx, 0)
    sens_next = phi_x @ sens + ca.horzcat(ca.SX(nx, nx), phi_p)
    return ca.Function(
        "rk4_substep_sens",
        [x, sens, u, p, s, h],
        [x_next, sens_next],
        ["x", "S", "u", "p", "s", "h"],
        ["x_next", "S_next"],
    )


def state_substep_function(model: Model) -> ca.Function:
    """SX function (x, u, p, s, h) -> x_next: the substep without sensitivities, for
    evaluations that need only residuals (about 20x cheaper)."""
    x, u, p, s, h = _rk4_symbols(model)
    return ca.Function(
        "rk4_substep",
        [x, u, p, s, h],
        [rk4_substep(model.dynamics, x, u, p, s, h)],
        ["x", "u", "p", "s", "h"],
        ["x_next"],
    )


def _compile(function: ca.Function) -> ca.Function:
    """``function`` as native code (``native.compile_function``), or as it is where no
    compiler builds it."""
    compiled = native.compile_function(function, COMPILE_FLAGS, NATIVE_FLAGS)
    return function if compiled is None else compiled


class WindowKernel:
    """``hf_windows`` of a compiled library (see DRIVER): integrates shooting windows."""

    def __init__(self, library: Path):
        self._lib = ctypes.CDLL(str(library))  # kept: the function lives in it
        pointer = ctypes.c_void_p
        self._fn = self._lib.hf_windows
        self._fn.restype = ctypes.c_int
        self._fn.argtypes = [pointer] * 4 + [ctypes.c_double] + [ctypes.c_int] * 4 + [pointer] * 2

    def __call__(self, arrays: dict, h: float, n_sub: int, m: int, count: int, threads: int):
        """Integrate ``count`` windows of ``m`` samples, ``n_sub`` substeps of ``h`` [s] each,
        from C-contiguous float arrays "x0", "u", "p", "s" into "xs" (and "ss" if present),
        laid out as for ``window_function``. Returns the status (0: success)."""
        ss = arrays.get("ss")
        return self._fn(
            *(arrays[name].ctypes.data for name in ("x0", "u", "p", "s")),
            h,
            n_sub,
            m,
            count,
            threads,
            arrays["xs"].ctypes.data,
            None if ss is None else ss.ctypes.data,
        )


@lru_cache(maxsize=16)
def compiled_windows(model: Model, free: tuple[int, ...] | None) -> WindowKernel | None:
    """The window loop compiled with the substep (with sensitivities to the ``free``
    parameters; None: without sensitivities), or None if it cannot be built here."""
    function = state_substep_function(model) if free is None else substep_function(model, free)
    nd = 0 if free is None else model.n_states + len(free)
    sizes = {"FN": function.name(), "NX": model.n_states, "ND": nd, "NU": model.n_inputs}
    defines = "".join(f"#define {key} {value}\n" for key, value in sizes.items())
    name = f"{function.name()}_windows"
    source = native.c_source(function) + defines + DRIVER
    library = native.build(name, source, (*COMPILE_FLAGS, "-pthread"), NATIVE_FLAGS)
    return None if library is None else WindowKernel(library)


@lru_cache(maxsize=16)
def compiled_substep(model: Model, free: tuple[int, ...], compile_c: bool = True) -> ca.Function:
    """The substep with sensitivities, compiled to C where a compiler exists (cached)."""
    function = substep_function(model, free)
    return _compile(function) if compile_c else function


@lru_cache(maxsize=16)
def compiled_state_substep(model: Model, compile_c: bool = True) -> ca.Function:
    """The substep without sensitivities, compiled to C where a compiler exists (cached)."""
    function = state_substep_function(model)
    return _compile(function) if compile_c else function


@lru_cache(maxsize=64)
def window_function(
    substep: ca.Function, n_substeps: int, n_samples: int, n_windows: int, n_threads: int
) -> ca.Function:
    """All shooting windows at once: (X0, U, p, s, h) -> (X, S), or -> X for a substep
    without sensitivities.

    X0 : (n_x, W) node states; U : (n_u, W * n_samples) inputs, window by window;
    X : (n_x, W * n_samples) states after each sample; S : (n_x, W * n_samples * n_d)
    their sensitivities to (x0, p_free), sample by sample.
    """
    with_sens = substep.n_out() == 2
    nx = substep.size1_in(0)
    nd = substep.size2_in(1) if with_sens else 0
    nu = substep.size1_in(1 + with_sens)
    n_p = substep.size1_in(2 + with_sens)
    carry = [ca.MX.sym("x", nx)] + ([ca.MX.sym("S", nx, nd)] if with_sens else [])
    shared = [ca.MX.sym("u", nu), ca.MX.sym("p", n_p), ca.MX.sym("s", 2), ca.MX.sym("h")]
    state = carry
    for _ in range(n_substeps):
        state = substep.call([*state, *shared])
    sample = ca.Function("sample", [*carry, *shared], state)
    # mapaccum: accumulate (x, S); u is taken column by column; p, s, h are repeated.
    trajectory = sample.mapaccum("window", n_samples, len(carry))
    x0 = ca.MX.sym("x0", nx)
    start = [x0] + ([ca.horzcat(ca.DM.eye(nx), ca.DM(nx, nd - nx))] if with_sens else [])
    uu = ca.MX.sym("U", nu, n_samples)
    window = ca.Function(
        "window", [x0, uu, *shared[1:]], trajectory.call([*start, uu, *shared[1:]])
    )
    parallel = "thread" if n_threads > 1 and n_windows > 1 else "serial"
    # p, s and h (inputs 2-4) are shared by all windows, not repeated.
    return window.map("windows", parallel, n_windows, [2, 3, 4], [], {"max_num_threads": n_threads})
