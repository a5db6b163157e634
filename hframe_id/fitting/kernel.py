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


def cache_dir() -> Path:
    root = os.environ.get(CACHE_ENV)
    if root:
        return Path(root)
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "hframe-id"


def substep_function(model: Model, free: tuple[int, ...]) -> ca.Function:
    """SX function (x, S, u, p, s, h) -> (x_next, S_next) of one RK4 substep of length h.

    ``free`` are the indices (in ``model.parameters``) of the parameters whose sensitivities
    are carried; S has n_x + len(free) columns.
    """
    nx, nu, n_p = model.n_states, model.n_inputs, len(model.parameters)
    x = ca.SX.sym("x", nx)
    sens = ca.SX.sym("S", nx, nx + len(free))
    u = ca.SX.sym("u", nu)
    p = ca.SX.sym("p", n_p)
    s = ca.SX.sym("s", 2)
    h = ca.SX.sym("h")

    def f(state: ca.SX) -> ca.SX:
        return model.dynamics(state, u, p, s)

    k1 = f(x)
    k2 = f(x + h / 2 * k1)
    k3 = f(x + h / 2 * k2)
    k4 = f(x + h * k3)
    x_next = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
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


def _compile(function: ca.Function) -> ca.Function:
    """Compile ``function`` to a shared library (cached by source hash) and load it."""
    compiler = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if compiler is None:
        return function
    with tempfile.TemporaryDirectory() as tmp:
        source = Path(tmp) / "kernel.c"
        cg = ca.CodeGenerator("kernel.c", {"with_header": False})
        cg.add(function)
        cg.generate(str(Path(tmp)) + os.sep)
        code = source.read_text()
    digest = hashlib.sha256((code + " ".join(COMPILE_FLAGS)).encode()).hexdigest()[:20]
    directory = cache_dir() / "kernels"
    library = directory / f"{function.name()}-{digest}.so"
    if not library.exists():
        directory.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=directory) as tmp:
            src = Path(tmp) / "kernel.c"
            src.write_text(code)
            out = Path(tmp) / "kernel.so"
            result = subprocess.run(
                [compiler, *COMPILE_FLAGS, str(src), "-o", str(out), "-lm"],
                capture_output=True,
                text=True,
            )
            if result.returncode != 0:
                return function
            os.replace(out, library)
    return ca.external(function.name(), str(library))


@lru_cache(maxsize=16)
def compiled_substep(model: Model, free: tuple[int, ...], compile_c: bool = True) -> ca.Function:
    """The substep with sensitivities, compiled to C where a compiler exists (cached)."""
    function = substep_function(model, free)
    return _compile(function) if compile_c else function


@lru_cache(maxsize=64)
def window_function(
    substep: ca.Function, n_substeps: int, n_samples: int, n_windows: int, n_threads: int
) -> ca.Function:
    """All shooting windows at once: (X0, U, p, s, h) -> (X, S).

    X0 : (n_x, W) node states; U : (n_u, W * n_samples) inputs, window by window;
    X : (n_x, W * n_samples) states after each sample; S : (n_x, W * n_samples * n_d)
    their sensitivities to (x0, p_free), sample by sample.
    """
    nx = substep.size1_in(0)
    nd = substep.size2_in(1)
    nu = substep.size1_in(2)
    n_p = substep.size1_in(3)
    x = ca.MX.sym("x", nx)
    sens = ca.MX.sym("S", nx, nd)
    u = ca.MX.sym("u", nu)
    p = ca.MX.sym("p", n_p)
    s = ca.MX.sym("s", 2)
    h = ca.MX.sym("h")
    xk, sk = x, sens
    for _ in range(n_substeps):
        xk, sk = substep(xk, sk, u, p, s, h)
    sample = ca.Function("sample", [x, sens, u, p, s, h], [xk, sk])
    # mapaccum: accumulate (x, S); u is taken column by column; p, s, h are repeated.
    trajectory = sample.mapaccum("window", n_samples, 2)
    x0 = ca.MX.sym("x0", nx)
    uu = ca.MX.sym("U", nu, n_samples)
    s0 = ca.DM.eye(nx)
    s0 = ca.horzcat(s0, ca.DM(nx, nd - nx))
    xs, ss = trajectory(x0, s0, uu, p, s, h)
    window = ca.Function("window", [x0, uu, p, s, h], [xs, ss])
    parallel = "thread" if n_threads > 1 and n_windows > 1 else "serial"
    # p, s and h (inputs 2-4) are shared by all windows, not repeated.
    return window.map("windows", parallel, n_windows, [2, 3, 4], [], {"max_num_threads": n_threads})
