"""The fixed-step RK4 of the simulators against a tight Radau reference (scipy solve_ivp).

For each variant (Coulomb friction on: Table 2.3, Table 4.2, Table 3.1 with Coulomb added) the
input is 2-10 V: a step, a reversal through zero velocity (the stiff knee of the smoothed
Coulomb law) and 0 V (coasting to a stop, where the stiff friction mode sits). The reference
integrates each constant-input segment with Radau, rtol 1e-10, atol 1e-11 (m, rad, m/s,
rad/s), with the exact Jacobian, and is sampled at the same 1 ms instants.

Documented bound (docs/friction.md, integrators.py), default substeps (``stable_substeps``):
positions within 2 um and velocities within 0.5 mm/s, angles counted as belt length r phi.
Measured: about 0.3-0.8 um and 0.03-0.15 mm/s, so the bound has 2.5-3x margin; it is 5x one
encoder count (r 2 pi / 321084 = 0.38 um) and well below the 5 um laser noise. With 3 substeps (RK4
outside its stability interval for the friction mode) the error exceeds both bounds: the test
can fail.
"""

import copy
import dataclasses
import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hframe_id.fitting import FitOptions, kernel
from hframe_id.fitting.problem import build_problem, output_matrix
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording
from hframe_id.simulation.friction import friction_sites
from hframe_id.simulation.integrators import (
    RK4_STABILITY_LIMIT,
    rk4_step,
    spectral_radius_at_rest,
    stability_substeps,
    stable_substeps,
    substeps_for_radius,
)
from hframe_id.simulation.open_loop import simulate

MODELS = Path(__file__).resolve().parents[2] / "models"
DT = 1e-3
POSITION_BOUND_M = 2e-6
VELOCITY_BOUND_M_PER_S = 5e-4


def _hframe20_with_coulomb():
    # Table 3.1 has no Coulomb friction; Table 4.2's levels split over the lumped pulleys:
    # J_M = 2 J_p and B_M = 2 B_p (eq. 4.2, 4.4), so tau_c per pulley = 0.05 / 2 N m.
    params = load_parameter_file(MODELS / "hframe-20-table3.1.yaml")
    changes = {f"tau_c{i}": 0.025 for i in range(1, 9)}
    return params.replace_values(F_c_cart=0.4, F_c_bridge=2.0, **changes)


CASES = {
    "one-axis": lambda: load_parameter_file(MODELS / "one-axis-table2.3.yaml"),
    "hframe-8": lambda: load_parameter_file(MODELS / "hframe-8-table4.2.yaml"),
    "hframe-20": _hframe20_with_coulomb,
}


def _inputs(n_inputs: int) -> np.ndarray:
    t = np.arange(150) * DT
    u1 = np.select([t < 0.05, t < 0.1], [10.0, -2.0], 0.0)
    u2 = np.select([t < 0.05, t < 0.1], [2.0, -10.0], 0.0)
    return np.column_stack([u1, u2])[:, :n_inputs]


class NumpyDynamics:
    """The same xdot as ``model.dynamics``, in NumPy, for a fast Radau reference.

    With constant belt stiffness and a constant mass matrix the equations are linear except
    for the Coulomb terms: xdot = A x + B u - [0; M^-1 F_c tanh(v / v_s)]. A and B are CasADi's
    exact Jacobians with Coulomb friction removed; ``check`` confirms the decomposition
    against ``model.dynamics`` at random states (a 50 us CasADi call per Radau evaluation
    would make the reference ten times slower).
    """

    def __init__(self, model, p):
        self.model, self.p = model, np.asarray(p, dtype=float)
        self.smoothing = ca.DM(model.options.smoothing)
        sites = friction_sites(model)
        p_linear = self.p.copy()
        p_linear[[site.coulomb for site in sites]] = 0.0
        x = ca.SX.sym("x", model.n_states)
        u = ca.SX.sym("u", model.n_inputs)
        xdot = model.dynamics(x, u, p_linear, self.smoothing)
        zero = (np.zeros(model.n_states), np.zeros(model.n_inputs))
        self.a = ca.Function("a", [x, u], [ca.jacobian(xdot, x)])(*zero).full()
        self.b = ca.Function("b", [x, u], [ca.jacobian(xdot, u)])(*zero).full()
        self.n_q = model.n_states // 2
        inverse_mass = np.linalg.inv(model.mass(self.p).full())
        self.rate = np.array([self.n_q + site.coordinate for site in sites])
        self.columns = inverse_mass[:, [site.coordinate for site in sites]]
        self.levels = np.array([self.p[site.coulomb] for site in sites])
        self.v_s = np.array([self.smoothing[0 if site.linear else 1] for site in sites]).ravel()

    def __call__(self, x, u):
        friction = self.levels * np.tanh(x[self.rate] / self.v_s)
        xdot = self.a @ x + self.b @ u
        xdot[self.n_q :] -= self.columns @ friction
        return xdot

    def jacobian(self, x, _u):
        slope = self.levels / self.v_s * (1.0 - np.tanh(x[self.rate] / self.v_s) ** 2)
        jac = self.a.copy()
        jac[self.n_q :, self.rate] -= self.columns * slope
        return jac

    def check(self, rng):
        for _ in range(20):
            x = rng.normal(size=self.model.n_states) * np.r_[[1e-2] * self.n_q, [1e-1] * self.n_q]
            x[self.rate[0]] = rng.normal() * 1e-2  # near the tanh knee too
            u = rng.uniform(-10, 10, self.model.n_inputs)
            exact = self.model.dynamics(x, u, self.p, self.smoothing).full().ravel()
            np.testing.assert_allclose(self(x, u), exact, rtol=1e-9, atol=1e-9)


def _radau(model, p, inputs: np.ndarray) -> np.ndarray:
    f = NumpyDynamics(model, p)
    f.check(np.random.default_rng(0))
    states = [np.zeros(model.n_states)]
    k = 0
    while k < inputs.shape[0]:
        end = k
        while end + 1 < inputs.shape[0] and np.array_equal(inputs[end + 1], inputs[k]):
            end += 1
        solution = solve_ivp(
            lambda _t, xx, uk: f(xx, uk),
            (k * DT, (end + 1) * DT),
            states[-1],
            method="Radau",
            rtol=1e-10,
            atol=1e-11,
            jac=lambda _t, xx, uk: f.jacobian(xx, uk),
            t_eval=np.arange(k + 1, end + 2) * DT,
            args=(inputs[k],),
        )
        assert solution.success, solution.message
        states.extend(solution.y.T)
        k = end + 1
    return np.array(states)


@pytest.fixture(scope="module", params=list(CASES))
def case(request):
    params = CASES[request.param]()
    model = build_model(params.variant)
    p = model.parameter_vector(params.values)
    inputs = _inputs(model.n_inputs)
    # Belt-length units: r phi for angles, so positions and velocities compare in m and m/s.
    scale = np.array([params.values["r"] if c.unit == "rad" else 1.0 for c in model.coordinates])
    return model, p, inputs, _radau(model, p, inputs), np.concatenate([scale, scale])


def _errors(model, states, reference, scale):
    error = np.abs(states - reference) * scale
    n_q = model.n_states // 2
    return error[:, :n_q].max(), error[:, n_q:].max()


def test_rk4_default_substeps_within_bound(case):
    model, p, inputs, reference, scale = case
    states = simulate(model, p, inputs, DT)
    position, velocity = _errors(model, states, reference, scale)
    print(f"{model.variant}: {stable_substeps(model, p, DT)} substeps, position error "
          f"{position:.2e} m, velocity error {velocity:.2e} m/s")  # fmt: skip
    assert position <= POSITION_BOUND_M
    assert velocity <= VELOCITY_BOUND_M_PER_S


def test_reference_detects_too_few_substeps(case):
    # 3 substeps: |lambda h| ~ 15 for the friction mode, far outside RK4's stability interval.
    # tanh saturates, so the velocity chatters around zero instead of blowing up; the error
    # still exceeds both bounds (measured 3-6x).
    model, p, inputs, reference, scale = case
    states = simulate(model, p, inputs, DT, n_substeps=3)
    position, velocity = _errors(model, states, reference, scale)
    assert position > POSITION_BOUND_M
    assert velocity > VELOCITY_BOUND_M_PER_S


def test_compiled_equals_virtual_machine(case):
    # Native code (gcc -O3, no fast-math) evaluates the same operations: equal to round-off.
    model, p, inputs, reference, scale = case
    vm = simulate(model, p, inputs, DT)
    native = simulate(model, p, inputs, DT, compiled=True)
    np.testing.assert_allclose(native, vm, rtol=1e-9, atol=1e-12)


# ---------------------------------------------------------------- simulator == fitter, bitwise
# One RK4 (``integrators.rk4_substep``) under the simulator, the sim rig and the fitter: on the
# same parameters, inputs, initial state, substep count and step, the fitter's shooting windows
# must reproduce the simulator's states and residuals exactly, not to a tolerance. Exact is
# possible because every path runs the same IEEE operations in the same order: the simulator
# and the sim rig evaluate the SX graph in CasADi's virtual machine; the fitter's kernels are
# that graph with h a symbol (h / 2 and h / 6 rounded at run time instead of by Python: the
# same doubles), compiled without value-changing flags (``kernel.COMPILE_FLAGS``, no FMA
# contraction) or run in the same virtual machine. Not covered: ``simulate(compiled=True)``,
# built with -O3 -freciprocal-math, -march=native (FMA contraction) and its own tanh
# (``simulation.compiled``) for speed; it agrees with the virtual machine to ~4e-14 here
# (``test_compiled_equals_virtual_machine``) and the fitter never uses it.


@pytest.fixture(scope="module")
def shooting():
    truth = load_parameter_file(MODELS / "hframe-8-table4.2.yaml")
    # A start, a reversal through zero velocity (stiff knee) and coasting to rest.
    voltages = np.zeros((400, 2))
    voltages[50:200] = (-4.0, 2.0)
    voltages[200:300] = (6.0, -3.0)
    problem = build_problem([simulate_recording(truth, voltages, seed=4)], truth, FitOptions())
    ms = MultipleShooting(problem).uniform()
    theta = np.zeros(len(problem.free))
    p = problem.parameters(theta)
    smoothing = problem.smoothing
    n_sub = ms.substep_plan(p, smoothing)["stiff"]
    inputs = problem.experiments[0].inputs
    states = simulate(ms.model, p, inputs, ms.dt, n_substeps=n_sub, smoothing=smoothing)
    return ms, theta, p, smoothing, n_sub, states


def _window_states(ms, states):
    """(W, M + 1, n_x) the simulator's states laid out as the fitter's windows, and the
    (W, M + 1) mask of the samples that exist (the last window may be short)."""
    index = ms.window_start[:, None] + np.arange(ms.m + 1)
    exists = np.arange(ms.m + 1) <= ms.window_length[:, None]
    return states[np.minimum(index, len(states) - 1)], exists


def test_stiff_substeps_are_the_simulators(shooting):
    # The fitter's stiff count is ``stable_substeps`` with the fit's safety, its fast count as
    # the minimum and its max_substeps as the cap (at the start and at other parameters).
    ms, theta, p, smoothing, n_sub, states = shooting
    options = ms.transcription
    rng = np.random.default_rng(1)
    for step in [theta, *(rng.normal(size=theta.size) for _ in range(5))]:
        p = ms.problem.parameters(step)
        for s in (smoothing, (1e-2, 1e-1)):
            plan = ms.substep_plan(p, s)
            expected = stable_substeps(
                ms.model, p, ms.dt, s, options.substep_safety, plan["fast"], options.max_substeps
            )
            assert plan["stiff"] == expected
    assert n_sub > 4


@pytest.mark.parametrize("radius", [10.0, 4.5e4, 9.3e5, 1e7])
def test_a_cap_never_takes_the_count_below_stability(radius):
    # The cap limits the safety margin only: at every radius [1/s] the count keeps
    # |lambda| h <= 2.785 (a rig-04 fit at 9.3e5 1/s, capped at 200 of the 334 needed, had
    # transition matrices of radius 1e100), and below the cap it is the safe count.
    dt = 1e-3
    for cap in (4, 200, 400):
        n = substeps_for_radius(radius, dt, 1.5, 4, cap)
        assert radius * dt / n <= RK4_STABILITY_LIMIT
        assert n == max(
            min(max(math.ceil(radius * dt * 1.5 / RK4_STABILITY_LIMIT), 4), cap),
            stability_substeps(radius, dt),
        )
    assert stability_substeps(9.3e5, dt) == 334


def test_a_point_too_stiff_for_max_substeps_is_refused(shooting):
    # With max_substeps one below the count stability needs at rest, the evaluation
    # integrates nothing and is refused (infinite cost, undefined derivatives); with it
    # equal, it is the ordinary evaluation (stable, the safety margin capped).
    ms, theta, p, smoothing, n_sub, states = shooting
    stable = stability_substeps(spectral_radius_at_rest(ms.model, p, smoothing), ms.dt)
    assert 4 < stable < n_sub
    for cap, refused in ((stable - 1, True), (stable, False)):
        options = dataclasses.replace(ms.transcription, max_substeps=cap)
        capped = MultipleShooting(ms.problem, transcription=options).uniform()
        assert capped.substep_plan(p, smoothing)["refused"] is refused
        nodes, _ = capped.initial_nodes(p)
        ev = capped.evaluate(nodes, theta, smoothing)
        assert bool(np.isfinite(ev.cost)) is not refused
        assert bool(np.all(np.isnan(ev.jac_theta))) is refused


def test_sim_rig_step_is_the_simulator(shooting):
    # SimRig steps the plant with ``rk4_step`` one sample at a time.
    ms, theta, p, smoothing, n_sub, states = shooting
    step = rk4_step(ms.model, n_sub, ms.dt)
    x = states[0]
    rig = [x]
    for u in ms.problem.experiments[0].inputs:
        x = np.asarray(step(x, u, p, ca.DM(smoothing))).ravel()
        rig.append(x)
    np.testing.assert_array_equal(np.array(rig), states)


@pytest.mark.parametrize("loop", ["native", "casadi-map"])
@pytest.mark.parametrize("derivatives", [True, False])
def test_fitter_windows_are_bitwise_the_simulator(shooting, loop, derivatives):
    """The fitter's states and weighted residuals from nodes on the simulated trajectory equal
    the simulator's exactly, through the compiled window loop ("native", where a C compiler
    exists) and through CasADi's mapped window function ("casadi-map")."""
    ms, theta, p, smoothing, n_sub, states = shooting
    if loop == "native":
        if ms.native[derivatives] is None:
            pytest.skip("no C compiler: the fitter has no native window loop here")
    else:
        ms = copy.copy(ms)
        ms.native, ms._buffers = {True: None, False: None}, {}
    expected, exists = _window_states(ms, states)
    ev = ms.evaluate(expected[:, 0], theta, smoothing, derivatives=derivatives)
    assert ev.n_substeps == (n_sub, n_sub)
    np.testing.assert_array_equal(ev.states[exists], expected[exists])
    y = expected[:, : ms.m] @ output_matrix(ms.model).T
    residual = ms.weight * (y - ms.measured)
    np.testing.assert_array_equal(ev.residual[exists[:, : ms.m]], residual[exists[:, : ms.m]])


@pytest.mark.parametrize("derivatives", [True, False])
def test_kernel_in_the_virtual_machine_is_bitwise_the_simulator(shooting, derivatives):
    """The fitter's substep kernels evaluated by CasADi's SX virtual machine (no compiled code
    at all, as without a C compiler) over all windows equal the simulator's states exactly."""
    ms, theta, p, smoothing, n_sub, states = shooting
    free = tuple(ms.problem.free)
    if derivatives:
        substep = kernel.substep_function(ms.model, free)
    else:
        substep = kernel.state_substep_function(ms.model)
    windows = kernel.window_function(substep, n_sub, ms.m, ms.n_windows, 1)
    expected, exists = _window_states(ms, states)
    u = ms.inputs.reshape(-1, ms.nu).T
    out = windows(expected[:, 0].T, u, p, ca.DM(smoothing), ms.dt / n_sub)
    xs = np.asarray(out[0] if derivatives else out).T.reshape(ms.n_windows, ms.m, ms.nx)
    np.testing.assert_array_equal(xs[exists[:, 1:]], expected[:, 1:][exists[:, 1:]])
