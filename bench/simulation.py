"""Simulation speed: the closed-loop 1 in square and the open-loop 0.8 s step on hframe-8.

Targets (issue 3): the closed loop at >= 200x real time (the 0.833 s square in <= 4 ms) and the
open-loop 0.8 s step in <= 2 ms. Each line gives the median wall time, the real-time factor and
the speed-up over baselines timed in the same run:

- ``python loop``: the same RK4 step (CasADi VM) called from Python once per sample, with the
  Appendix A PID in Python (what a straightforward implementation does);
- ``scipy``: ``solve_ivp`` (LSODA, rtol 1e-8) per sample with the PID in Python (closed loop),
  or over the whole step (open loop), on the NumPy-wrapped model.

The fast paths map one sample function over the horizon (``mapaccum``) and run it as native
code (gcc, cached on disk); "mapped, VM" is the same graph in CasADi's virtual machine. Timings
are not asserted anywhere: shared 2-core machines are noisy, the ratios are the result.
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp

from bench import heading, median_time
from hframe_id.control.closed_loop import closed_loop_horizon, simulate_closed_loop
from hframe_id.control.pid import ControllerOptions, ResetWindupPID
from hframe_id.control.trajectory import motor_angles, square
from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from hframe_id.resources import models_dir
from hframe_id.simulation.compiled import evaluate
from hframe_id.simulation.friction import FrictionOptions
from hframe_id.simulation.integrators import rk4_step, stable_substeps
from hframe_id.simulation.open_loop import _trajectory_function, simulate

MODELS = models_dir()
PLANT = MODELS / "hframe-8-table4.2.yaml"
DT = 1e-3
CLOSED_LOOP_TARGET_S = 4e-3
OPEN_LOOP_TARGET_S = 2e-3
OPEN_LOOP_S = 0.8


def _python_closed_loop(model, p, trajectory, controller, n_substeps):
    step = rk4_step(model, n_substeps, DT)
    s = ca.DM(model.options.smoothing)
    times = trajectory.sample_times(DT)
    reference = motor_angles(trajectory.position(times), p[model.index("parameter", "r")])
    loops = [ResetWindupPID(controller.motor1), ResetWindupPID(controller.motor2)]
    x = np.zeros(model.n_states)
    for k in range(times.size - 1):
        u = [loops[i].step(x[2 + i], reference[k, i]) for i in range(2)]
        x = step(x, u, p, s).full().ravel()
    return x


def _scipy_closed_loop(model, p, trajectory, controller):
    x_sym, u_sym = ca.SX.sym("x", model.n_states), ca.SX.sym("u", 2)
    f = ca.Function("f", [x_sym, u_sym], [model.f(x_sym, u_sym, p)])
    times = trajectory.sample_times(DT)
    reference = motor_angles(trajectory.position(times), p[model.index("parameter", "r")])
    loops = [ResetWindupPID(controller.motor1), ResetWindupPID(controller.motor2)]
    x = np.zeros(model.n_states)
    for k in range(times.size - 1):
        u = np.array([loops[i].step(x[2 + i], reference[k, i]) for i in range(2)])
        x = solve_ivp(
            lambda _t, xx, uu: f(xx, uu).full().ravel(), (0, DT), x, "LSODA",
            rtol=1e-8, atol=1e-11, args=(u,),
        ).y[:, -1]  # fmt: skip
    return x


def _rate(label: str, seconds: float, simulated_s: float, base: dict[str, float]) -> str:
    ratios = ", ".join(f"{seconds_b / seconds:7.1f}x {name}" for name, seconds_b in base.items())
    return f"  {label:34s} {1e3 * seconds:9.2f} ms  {simulated_s / seconds:9.0f}x real time" + (
        f"   ({ratios})" if ratios else ""
    )


def closed_loop_lines(repeats: int = 21) -> list[str]:
    """Benchmark lines of the closed loop (square trajectory, PID gains 150/100/4): median
    of ``repeats`` runs against the baselines timed in the same call."""
    params = load_parameter_file(PLANT)
    model = build_model(params.variant)
    p = model.parameter_vector(params.values)
    trajectory = square()
    controller = ControllerOptions.from_gains(150, 100, 4)
    n = stable_substeps(model, p, DT)
    n_samples = trajectory.sample_times(DT).size - 1
    simulated = n_samples * DT

    start = time.perf_counter()
    simulate_closed_loop(model, p, trajectory, controller, compiled=True)
    first = time.perf_counter() - start
    horizon = closed_loop_horizon(model, n, DT, n_samples, "smooth", True)
    args = [
        np.zeros(model.n_states + 4),
        motor_angles(trajectory.position(trajectory.sample_times(DT)[:-1]), params.values["r"]),
        p,
        np.array(model.options.smoothing),
        np.array(controller.gain_vector()),
        np.array([-10.0, 10.0]),
    ]
    base = {
        "python loop": median_time(
            lambda: _python_closed_loop(model, p, trajectory, controller, n), repeats=3
        ),
        "scipy": median_time(
            lambda: _scipy_closed_loop(model, p, trajectory, controller), repeats=1, warmup=0
        ),
    }
    native = median_time(lambda: evaluate(horizon, args), repeats=repeats)
    full = median_time(
        lambda: simulate_closed_loop(model, p, trajectory, controller, compiled=True),
        repeats=repeats,
    )
    vm = median_time(lambda: simulate_closed_loop(model, p, trajectory, controller), repeats=5)
    stick = median_time(
        lambda: simulate_closed_loop(
            model, p, trajectory, controller, FrictionOptions("stick-slip"), compiled=True
        ),
        repeats=repeats,
    )
    lines = [
        f"Closed loop: 1 in square ({simulated:.3f} s, {n_samples} samples), {params.variant} "
        f"Table 4.1 + 4.2, PID 150/100/4, RK4 x {n} substeps; first call (build + gcc or "
        f"cache) {first:.2f} s",
        _rate("mapped, native (horizon call)", native, simulated, base),
        _rate("simulate_closed_loop, native", full, simulated, base),
        _rate("simulate_closed_loop, CasADi VM", vm, simulated, base),
        _rate("stick-slip friction, native", stick, simulated, base),
        _rate("baseline: python loop", base["python loop"], simulated, {}),
        _rate("baseline: scipy LSODA per sample", base["scipy"], simulated, {}),
        f"  target <= {1e3 * CLOSED_LOOP_TARGET_S:.0f} ms "
        f"(>= {simulated / CLOSED_LOOP_TARGET_S:.0f}x): {_verdict(full, CLOSED_LOOP_TARGET_S)} "
        f"by simulate_closed_loop ({1e3 * full:.2f} ms), "
        f"{_verdict(native, CLOSED_LOOP_TARGET_S)} by the horizon call ({1e3 * native:.2f} ms)",
    ]
    return lines


def _verdict(seconds: float, target: float) -> str:
    return "met" if seconds <= target else "NOT met"


def open_loop_lines(repeats: int = 21) -> list[str]:
    """Benchmark lines of the open loop (the -4 V / -4 V step of section 4.4): the compiled
    horizon and ``simulate`` (median of ``repeats``) against a Python loop of RK4 steps and
    SciPy's LSODA, timed in the same call."""
    params = load_parameter_file(PLANT)
    model = build_model(params.variant)
    p = model.parameter_vector(params.values)
    n_samples = int(round(OPEN_LOOP_S / DT))
    inputs = np.tile([-4.0, -4.0], (n_samples, 1))  # the -4 V / -4 V step of section 4.4
    n = stable_substeps(model, p, DT)
    start = time.perf_counter()
    simulate(model, p, inputs, DT, compiled=True)
    first = time.perf_counter() - start
    horizon = _trajectory_function(model, n, DT, n_samples, "smooth", True)
    s = ca.DM(model.options.smoothing)
    x0 = np.zeros(model.n_states)
    step = rk4_step(model, n, DT)

    def python_loop():
        x = x0
        for k in range(n_samples):
            x = step(x, inputs[k], p, s).full().ravel()

    x_sym = ca.SX.sym("x", model.n_states)
    f = ca.Function("f", [x_sym], [model.f(x_sym, inputs[0], p)])

    def scipy_run():
        solve_ivp(lambda _t, xx: f(xx).full().ravel(), (0, OPEN_LOOP_S), x0, "LSODA",
                  rtol=1e-8, atol=1e-11, t_eval=np.arange(1, n_samples + 1) * DT)  # fmt: skip

    base = {
        "python loop": median_time(python_loop, repeats=3),
        "scipy": median_time(scipy_run, repeats=1, warmup=0),
    }
    native = median_time(
        lambda: evaluate(horizon, [x0, inputs, p, np.array(model.options.smoothing)]),
        repeats=repeats,
    )
    full = median_time(lambda: simulate(model, p, inputs, DT, compiled=True), repeats=repeats)
    vm = median_time(lambda: simulate(model, p, inputs, DT), repeats=5)
    return [
        f"Open loop: -4 V / -4 V step, {OPEN_LOOP_S} s ({n_samples} samples), {params.variant}, "
        f"RK4 x {n} substeps; first call {first:.2f} s",
        _rate("mapped, native (horizon call)", native, OPEN_LOOP_S, base),
        _rate("simulate, native", full, OPEN_LOOP_S, base),
        _rate("simulate, CasADi VM", vm, OPEN_LOOP_S, base),
        _rate("baseline: python loop", base["python loop"], OPEN_LOOP_S, {}),
        _rate("baseline: scipy LSODA", base["scipy"], OPEN_LOOP_S, {}),
        f"  target <= {1e3 * OPEN_LOOP_TARGET_S:.0f} ms: {_verdict(full, OPEN_LOOP_TARGET_S)} by "
        f"simulate ({1e3 * full:.2f} ms), {_verdict(native, OPEN_LOOP_TARGET_S)} by the horizon "
        f"call ({1e3 * native:.2f} ms)",
    ]


def run() -> list[str]:
    """Print and return the benchmark lines."""
    heading("Simulation speed (hframe-8, 1 ms samples)")
    lines = []
    for section in (closed_loop_lines, open_loop_lines):
        for line in section():
            print(line, flush=True)
            lines.append(line)
    return lines


if __name__ == "__main__":
    run()
