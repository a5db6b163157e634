"""The compiled inner loop of the fitter: one RK4 substep with its exact sensitivities.

Multiple shooting needs, for every sample of every shooting window, the state and its
derivatives with respect to the window's initial state and the free parameters. They are
propagated alongside the state, substep by substep (exact derivatives of the discrete RK4 map,
so the Gauss-Newton Jacobian is the Jacobian of the residuals actually computed):

    x+ = Phi(x, u, p, s, h),    S+ = dPhi/dx S + [0, dPhi/dp_free]

with S = d x / d(x_0, p_free). The substep is an SX graph (~10^4 flat instructions), generated
as C and compiled once per (model, free set); the compiled library is cached on disk, keyed by
the hash of its source, so later fits load it in milliseconds. Where no C compiler is
available, CasADi's SX virtual machine runs the same graph about 2x slower.

Samples, windows and experiments are then layered on top as MX ``mapaccum``/``map`` calls of
this one function: nothing is unrolled over the record (the naive unrolled graph of a six-file
fit does not fit in 24 GB).
"""

from __future__ import annotations

import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
from functools import lru_cache
from pathlib import Path

import casadi as ca

from hframe_id.models import Model

#: Where compiled kernels are kept (override with HFRAME_ID_CACHE).
CACHE_ENV = "HFRAME_ID_CACHE"
COMPILE_FLAGS = ("-O2", "-fPIC", "-shared")
#: Tried first: code for this machine's instruction set. VEX-encoded (AVX) code runs the
#: kernel 22 % faster on a Xeon with AVX-512 (an all-window evaluation 0.161 -> 0.124 s,
#: already with -mavx alone); contraction into FMAs stays off, so the results are bitwise
#: those of the portable build.
NATIVE_FLAGS = ("-march=native", "-ffp-contract=off")


def cache_dir() -> Path:
    root = os.environ.get(CACHE_ENV)
    if root:
        return Path(root)
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "hframe-id"


def _rk4_symbols(model: Model) -> tuple[ca.SX, ...]:
    """Symbols (x, u, p, s, h) of one substep: state, held input, parameters, smoothing
    velocities [m/s, rad/s] and substep length [s]."""
    return (
        ca.SX.sym("x", model.n_states),
        ca.SX.sym("u", model.n_inputs),
        ca.SX.sym("p", len(model.parameters)),
        ca.SX.sym("s", 2),
        ca.SX.sym("h"),
    )


def _rk4_step(model: Model, x: ca.SX, u: ca.SX, p: ca.SX, s: ca.SX, h: ca.SX) -> ca.SX:
    """The state after one classical RK4 substep of length h (one expression graph for both
    kernels, so their states agree bit for bit)."""

    def f(state: ca.SX) -> ca.SX:
        return model.dynamics(state, u, p, s)

    k1 = f(x)
    k2 = f(x + h / 2 * k1)
    k3 = f(x + h / 2 * k2)
    k4 = f(x + h * k3)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def substep_function(model: Model, free: tuple[int, ...]) -> ca.Function:
    """SX function (x, S, u, p, s, h) -> (x_next, S_next) of one RK4 substep of length h.

    ``free`` are the indices (in ``model.parameters``) of the parameters whose sensitivities
    are carried; S has n_x + len(free) columns.
    """
    nx = model.n_states
    x, u, p, s, h = _rk4_symbols(model)
    sens = ca.SX.sym("S", nx, nx + len(free))
    x_next = _rk4_step(model, x, u, p, s, h)
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
        [_rk4_step(model, x, u, p, s, h)],
        ["x", "u", "p", "s", "h"],
        ["x_next"],
    )


def _host() -> str:
    """What ``-march=native`` resolves from: the architecture and, on Linux, the CPU flags
    (a cache shared by different machines then keeps one native library per kind)."""
    flags = ""
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            flags = next((line for line in cpuinfo if line.startswith("flags")), "")
    except OSError:
        pass
    return f"{platform.machine()} {platform.processor()} {flags}"


def _compile(function: ca.Function) -> ca.Function:
    """Compile ``function`` to a shared library (cached by source hash) and load it: for
    this machine's instruction set if the compiler can, else portable code."""
    compiler = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if compiler is None:
        return function
    with tempfile.TemporaryDirectory() as tmp:
        source = Path(tmp) / "kernel.c"
        cg = ca.CodeGenerator("kernel.c", {"with_header": False})
        cg.add(function)
        cg.generate(str(Path(tmp)) + os.sep)
        code = source.read_text()
    for flags, host in (((*COMPILE_FLAGS, *NATIVE_FLAGS), _host()), (COMPILE_FLAGS, "")):
        library = _build(compiler, function.name(), code, flags, host)
        if library is not None:
            return ca.external(function.name(), str(library))
    return function


def _build(compiler: str, name: str, code: str, flags: tuple[str, ...], host: str):
    """Path of the shared library of ``code`` built with ``flags`` (cached by the hash of
    source, flags and ``host``), or None if the compiler fails."""
    digest = hashlib.sha256((code + " ".join(flags) + host).encode()).hexdigest()[:20]
    directory = cache_dir() / "kernels"
    library = directory / f"{name}-{digest}.so"
    if library.exists():
        return library
    directory.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=directory) as tmp:
        src = Path(tmp) / "kernel.c"
        src.write_text(code)
        out = Path(tmp) / "kernel.so"
        result = subprocess.run(
            [compiler, *flags, str(src), "-o", str(out), "-lm"],
            capture_output=True,
            text=True,
        )
        if result.returncode != 0:
            return None
        os.replace(out, library)
    return library


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
