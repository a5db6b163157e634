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

from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from hframe_id.simulation.friction import friction_sites
from hframe_id.simulation.integrators import stable_substeps
from hframe_id.simulation.open_loop import simulate

MODELS = Path(__file__).resolve().parents[1] / "models"
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
