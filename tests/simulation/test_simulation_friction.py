"""Open-loop simulation: physical oracles, the stick-slip option (Table 2.2), inputs."""

from pathlib import Path

import numpy as np
import pytest

from hframe_id.errors import OptionError
from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from hframe_id.simulation.friction import (
    FrictionOptions,
    dynamics_function,
    friction_sites,
    stick_slip_dynamics,
    stick_slip_substeps,
)
from hframe_id.simulation.inputs import MotorStep, step_inputs
from hframe_id.simulation.open_loop import simulate

MODELS = Path(__file__).resolve().parents[2] / "models"
STICK = FrictionOptions("stick-slip")


@pytest.fixture(scope="module")
def one_axis():
    params = load_parameter_file(MODELS / "one-axis-table2.3.yaml")
    model = build_model(params.variant)
    return model, model.parameter_vector(params.values), params.values


def _steady_rate(v, volts):
    """Power balance of the one-axis drive at constant speed (eq. 2.4 with Table 2.3 friction):
    g K_t/R u - K_t K_e/R w = (B_1 + B_2) w + tau_c1 + tau_c2 + r (b r w + F_c)."""
    drive = v["g_1"] * v["K_t"] / v["R"] * volts - v["tau_c1"] - v["tau_c2"] - v["r"] * v["F_c"]
    damping = v["K_t"] * v["K_e"] / v["R"] + v["B_1"] + v["B_2"] + v["b"] * v["r"] ** 2
    return drive / damping


@pytest.mark.parametrize("friction", [FrictionOptions(), STICK, FrictionOptions("sign")])
def test_steady_speed_matches_the_power_balance(one_axis, friction):
    # The slowest mode decays with about 65 ms: after 1.5 s the transient is below 1e-10.
    model, p, values = one_axis
    states = simulate(model, p, np.full((1500, 1), 10.0), friction=friction)
    rate = _steady_rate(values, 10.0)
    assert rate == pytest.approx(26.1, abs=0.05)
    assert states[-1, 3] == pytest.approx(rate, rel=1e-9)  # phi1_dot [rad/s]
    assert states[-1, 4] == pytest.approx(values["r"] * rate, rel=1e-9)  # cart [m/s]


def test_stick_slip_holds_below_breakaway_where_the_smooth_law_creeps(one_axis):
    # 0.3 V gives 9.7 mN m at the motor, below the 34 mN m of Coulomb friction of the whole
    # drive: a real drive does not move. Table 2.2's logic holds it exactly; the tanh law
    # lets it creep at a fraction of v_s (the price of smoothing, docs/friction.md).
    model, p, _ = one_axis
    inputs = np.full((1000, 1), 0.3)
    held = simulate(model, p, inputs, friction=STICK)
    creeping = simulate(model, p, inputs)
    assert np.abs(held).max() == 0.0
    cart = creeping[-1, 1]
    assert 20e-6 < cart < 200e-6  # m after 1 s: creep of ~0.3 v_s at the pulleys


def test_stick_slip_stops_without_reversing(one_axis):
    model, p, values = one_axis
    r = values["r"]
    x0 = np.array([0, 0, 0, 5.0, 5.0 * r, 5.0])  # coasting at 5 rad/s, belts unstretched
    coast = np.zeros((300, 1))
    states = simulate(model, p, coast, x0=x0, friction=STICK)
    smooth = simulate(model, p, coast, x0=x0)
    rates = states[:, [3, 5]]
    band = STICK.band_angular_rad_per_s
    assert rates.min() >= -band  # passive: it never drives the pulleys backwards
    assert np.abs(states[-100:, 3:]).max() <= band  # and it has "stopped" (inside the band)
    # Table 2.2's artefact: inside the band friction cancels the active torque exactly, so a
    # pulley keeps the speed it entered the band with (here 0.0097 rad/s) and the cart creeps
    # on at up to r x band; the smooth law brings it to rest. They differ by that creep only.
    creep = values["r"] * band * 0.3
    assert abs(states[-1, 1] - smooth[-1, 1]) <= creep + 10e-6
    assert np.abs(smooth[-1, 3:]).max() < 1e-9


def test_stuck_coordinate_has_no_acceleration(one_axis):
    # Inside the band with |active torque| <= tau_c the friction equals the active torque.
    model, p, _ = one_axis
    f = stick_slip_dynamics(model)
    x = np.array([0, 1e-6, 0, 0.005, 0, 0])  # cart displaced 1 um: spring forces small
    xdot = f(x, [0.1], p, STICK.band).full().ravel()
    assert xdot[3] == 0.0


def test_the_sign_law_is_viscous_plus_coulomb_without_a_band(one_axis):
    """Simulink's Coulomb & Viscous Friction block (the EMPS benchmark's): b v + F_c sign(v),
    sign(0) = 0. At rest no friction acts (where stick-slip holds); sliding, it is the full
    Coulomb level at any speed (where tanh is still rising at 1 mm/s)."""
    model, p, _ = one_axis
    sign = dynamics_function(model, FrictionOptions("sign"))
    free = model.dynamics(np.zeros(6), [0.1], p * _frictionless(model), [1.0, 1.0]).full()
    at_rest = sign(np.zeros(6), [0.1], p, STICK.band).full()
    np.testing.assert_allclose(at_rest, free, rtol=1e-12)
    sliding = np.array([0, 0, 0, 0, 1e-6, 0])  # the cart at 1 um/s
    smooth = model.dynamics(sliding, [0.0], p, model.options.smoothing).full().ravel()
    # tanh(1e-6 / 1e-3) ~ 1e-3 of F_c: the sign law decelerates ~1000 x harder (measured 913).
    assert sign(sliding, [0.0], p, STICK.band).full().ravel()[4] < 500 * smooth[4] < 0


def _frictionless(model) -> np.ndarray:
    mask = np.ones(len(model.parameters))
    for site in friction_sites(model):
        mask[[site.viscous, site.coulomb]] = 0.0
    return mask


def test_stick_slip_substeps_resolve_the_band():
    params = load_parameter_file(MODELS / "hframe-8-table4.2.yaml")
    model = build_model(params.variant)
    p = model.parameter_vector(params.values)
    n = stick_slip_substeps(model, p, 1e-3, STICK.band)
    mass = np.diag(model.mass(p).full())
    for site in friction_sites(model):
        band = STICK.band[0] if site.linear else STICK.band[1]
        assert p[site.coulomb] / mass[site.coordinate] * 1e-3 / n <= band


def test_unknown_friction_model_rejected():
    with pytest.raises(OptionError, match="unknown friction model"):
        FrictionOptions("coulomb")
    with pytest.raises(OptionError):
        FrictionOptions("stick-slip", band_angular_rad_per_s=0)


def test_steps_and_pulses_are_held_on_whole_samples():
    table = step_inputs(
        [MotorStep(1, 4.0), MotorStep(2, -6.0, start_s=0.05, duration_s=0.25)], 2, 0.5, 1e-3
    )
    assert table.shape == (500, 2)
    assert (table[:, 0] == 4.0).all()
    assert (table[:50, 1] == 0).all() and (table[50:300, 1] == -6.0).all()
    assert (table[300:, 1] == 0).all()
    assert MotorStep.parse("2,-6,0.05,0.25") == MotorStep(2, -6.0, 0.05, 0.25)


@pytest.mark.parametrize("text", ["1", "x,4", "1,4,0,0", "0,4", "1,4,-1", "1,2,3,4,5"])
def test_bad_steps_rejected(text):
    with pytest.raises(OptionError):
        MotorStep.parse(text)


def test_step_inputs_validate():
    with pytest.raises(OptionError, match="motor 2"):
        step_inputs([MotorStep(2, 1.0)], 1, 0.1)
    with pytest.raises(OptionError, match="sample time"):
        step_inputs([MotorStep(1, 1.0)], 1, 0.1, dt=-1e-3)
    with pytest.raises(OptionError, match="after the end"):
        step_inputs([MotorStep(1, 1.0, start_s=0.2)], 1, 0.1)


def test_simulate_rejects_wrong_input_width(one_axis):
    model, p, _ = one_axis
    with pytest.raises(ValueError, match="1 columns"):
        simulate(model, p, np.zeros((10, 2)))
