"""The stiffness wall as a constraint of the Gauss-Newton step, and the parameters that put
a fit against it (``fitting.stiffness_wall``)."""

import dataclasses

import numpy as np
import pytest

from hframe_id.fitting import FitOptions
from hframe_id.fitting.link_options import TranscriptionOptions
from hframe_id.fitting.problem import build_problem, default_free
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import GaussNewton, SolverState
from hframe_id.fitting.stiffness_wall import StiffnessWall, wall_parameters
from hframe_id.fitting.substep_plan import coulomb_rates, rest_and_moving_jacobians
from hframe_id.models import build_model
from hframe_id.recordings.simulated import simulate_recording
from hframe_id.simulation.integrators import (
    RK4_STABILITY_LIMIT,
    spectral_radius_at_rest,
    stability_substeps,
)
from hframe_id.simulation.open_loop import simulate


@pytest.fixture(scope="module")
def hframe(table):
    model = build_model(table.variant)
    p = np.array([table.values[spec.name] for spec in model.parameters])
    return model, p, [spec.name for spec in model.parameters]


def test_a_motors_coulomb_rate_at_rest_is_its_friction_over_smoothing_and_inertia(hframe):
    """The H-frame model's motor velocity row (eq. 3.10, friction eq. 3.6 smoothed by tanh(v /
    v_s)): its own rate at rest less that in motion is tau_c / (v_s J), to rounding."""
    model, p, names = hframe
    vs = model.options.smoothing
    rates = coulomb_rates(*rest_and_moving_jacobians(model, p, vs)[:2])
    motors = [i for i, c in enumerate(model.coordinates) if c.unit == "rad"]
    assert len(motors) == 2
    for k, i in enumerate(motors, start=1):
        tau, inertia = p[names.index(f"tau_cM{k}")], p[names.index(f"J_M{k}")]
        assert rates[i] == pytest.approx(tau / (vs[1] * inertia), rel=1e-9)


def test_no_parameter_is_at_the_wall_at_table_4_2(hframe):
    model, p, _ = hframe
    free = default_free(model)
    assert (
        wall_parameters(model, p, free, model.options.smoothing, 1e-3, TranscriptionOptions()) == ()
    )


def test_a_motor_whose_rate_caps_the_substeps_names_its_friction_and_inertia(hframe):
    """Motor 1's inertia lowered until its Coulomb rate alone needs the cap's substeps with
    the safety margin (the other motor well below): its J_M1 and tau_cM1 are the
    parameters at the wall, nothing else; a parameter held fixed is not named."""
    model, p, names = hframe
    options = TranscriptionOptions()
    vs = model.options.smoothing
    limit = options.max_substeps * RK4_STABILITY_LIMIT / (1e-3 * options.substep_safety)
    i = names.index("J_M1")
    tau = p[names.index("tau_cM1")]
    at_wall = p.copy()
    at_wall[i] = tau / (vs[1] * limit) / 1.01  # 1 % beyond the capped band's edge
    free = default_free(model)
    assert wall_parameters(model, at_wall, free, vs, 1e-3, options) == ("J_M1", "tau_cM1")
    fixed = [n for n in free if n != "tau_cM1"]
    assert wall_parameters(model, at_wall, fixed, vs, 1e-3, options) == ("J_M1",)
    below = p.copy()
    below[i] = tau / (vs[1] * limit) * 1.01
    assert wall_parameters(model, below, free, vs, 1e-3, options) == ()


def test_the_linearised_wall_of_a_fit_has_the_coulomb_elasticities(shooting_setup):
    """With motor 1's inertia halved, its Coulomb mode is the fastest at rest: the wall's
    normal in log-parameters is -1 along J_M1 and tau_c's share of the damping along
    tau_cM1 (the rate is (B + tau_c / v_s) / J), about 0 along the other motor's, and the
    margin is log(rho_wall / rho) for a wall half a substep inside max_substeps. (At Table
    4.2 itself the two motors' rates are close and the fastest mode is shared.)"""
    problem, ms, _, _ = shooting_setup
    names = problem.free_names
    index = np.arange(len(names))
    theta = np.zeros(len(index))
    theta[names.index("J_M1")] = -np.log(2.0)
    wall = StiffnessWall.at(ms, theta, index, problem.smoothing)
    normal = dict(zip(names, wall.normal, strict=True))
    # Forward differences at sqrt(eps): about 1e-8 of rounding. The eigenvalue is the
    # diagonal's rate only to within the belts' coupling of the modes (1.1e-4 on tau_cM1
    # here): 1e-3.
    assert normal["J_M1"] == pytest.approx(-1.0, abs=1e-3)
    # tau_c's share of the motor's damping at rest, (tau_c / v_s) / (B + tau_c / v_s).
    values = problem.initial.values
    coulomb = values["tau_cM1"] / problem.smoothing[1]
    assert normal["tau_cM1"] == pytest.approx(coulomb / (values["B_M1"] + coulomb), abs=1e-3)
    assert abs(normal["J_M2"]) < 1e-3
    rho = spectral_radius_at_rest(ms.model, problem.parameters(theta), problem.smoothing)
    rho_wall = (ms.transcription.max_substeps - 0.5) * RK4_STABILITY_LIMIT / ms.dt
    assert wall.margin == pytest.approx(np.log(rho_wall / rho), rel=1e-12)


def test_a_step_refused_for_stiffness_slides_along_the_wall(table):
    """Motor 1's inertia started 3 x above a plant's, with ``max_substeps`` so low that
    the plant's value is beyond the wall (stability at rest needs 17 substeps there, 9 are
    allowed): the Gauss-Newton steps that head for it are refused, and the stage's next
    iterate is the step constrained to the wall, which ends on it (its stability count
    the cap's), not a region cut tenfold that leaves it short of the wall."""
    plant = table.replace_values(J_M2=table.values["J_M2"] * 3)  # motor 2 never the wall
    u = np.zeros((400, 2))
    u[50:300] = (-4.0, 2.0)
    rec = simulate_recording(plant, u, seed=4)
    start = plant.replace_values(J_M1=table.values["J_M1"] * 3)
    problem = build_problem([rec], start, FitOptions(free=("J_M1", "k_b", "M_cart", "B_M1")))
    cap = 9
    ms = MultipleShooting(
        problem,
        transcription=dataclasses.replace(TranscriptionOptions(), max_substeps=cap),
    ).uniform()
    states = simulate(
        ms.model, problem.p_initial, problem.experiments[0].inputs, 1e-3, n_substeps=cap
    )
    gn = GaussNewton(ms)
    refused, accepted = [], []
    evaluate, accept = gn._evaluate, gn._accept

    def counting(state, nodes, theta, smoothing, derivatives=True):
        ev = evaluate(state, nodes, theta, smoothing, derivatives)
        refused.append(ev.n_substeps[1] > cap)
        return ev

    def keeping(walk, state, trial, iterations):
        accepted.append((len(refused), trial.theta.copy()))
        return accept(walk, state, trial, iterations)

    gn._evaluate, gn._accept = counting, keeping
    state = SolverState(states[ms.window_start], np.zeros(ms.nf), np.ones(ms.nf, dtype=bool))
    gn.run(state, "wall", problem.smoothing, 3, 1e-6, 1e-3)
    k = next(i for i, (n, _) in enumerate(accepted) if any(refused[:n]))
    before = accepted[k - 1][1] if k else np.zeros(ms.nf)
    after = accepted[k][1]
    # The region was 1 (it doubles from 0.5 after a long first step); a refusal alone cut
    # it tenfold, to 0.1, and the step with it (0.009 on the code before the wall).
    assert np.max(np.abs(after - before)) > 0.1
    rho = spectral_radius_at_rest(ms.model, problem.parameters(after), problem.smoothing)
    assert stability_substeps(rho, ms.dt) == cap
