"""The derived models against physics (energy, kinematics) and the thesis's printed equations.

The printed equations are oracles, not code: where they are right the derived model must agree
to rounding; where they carry a typo the test says which, and checks the derived value against
the corrected entry (and that it differs from the printed one, so the typo is real).
"""

from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hframe_id.analysis.linear import linearize
from hframe_id.errors import ModelError
from hframe_id.models import VARIANTS, ModelOptions, build_model
from hframe_id.parameters import ParameterSet, load_parameter_file

MODELS = Path(__file__).resolve().parents[2] / "models"
FILES = {
    "one-axis": "one-axis-table2.3.yaml",
    "hframe-20": "hframe-20-table3.1.yaml",
    "hframe-8": "hframe-8-table4.2.yaml",
}
# Unequal left/right values so that a swapped index in the derivation cannot hide.
ASYMMETRIC = {
    "one-axis": {"k2": 1.1e5, "J_2": 5.0e-5, "B_2": 0.0011, "g_1": 0.93},
    "hframe-20": {
        "k_2": 1.6e4,
        "k_4": 2.7e4,
        "k_6": 1.1e5,
        "J_2": 6.1e-5,
        "J_4": 4.9e-5,
        "J_6": 5.3e-5,
        "J_8": 6.6e-5,
        "B_2": 0.0017,
        "B_6": 0.0025,
        "g_2": 1.07,
    },
    "hframe-8": {"J_M2": 1.3e-4, "B_M2": 0.0047, "g_1": 0.95, "g_2": 1.05},
}

# Relative agreement of two float64 evaluations of the same expression (derived vs printed):
# both are sums of a handful of terms of up to ~1e8 magnitude, so ~1e-12 relative is rounding.
ROUNDING = 1e-10


def params_of(variant, **changes):
    params = load_parameter_file(MODELS / FILES[variant])
    return params.replace_values(**{**ASYMMETRIC[variant], **changes})


def accelerations(variant, values, q, qdot, u, options=None):
    model = build_model(variant, options)
    xdot = np.array(model.f(np.r_[q, qdot], u, model.parameter_vector(values))).ravel()
    return xdot[len(q) :]


def frictionless(variant):
    """Parameters with all viscous and Coulomb friction and the back-EMF set to zero."""
    params = params_of(variant)
    zero = {}
    for spec in build_model(variant).parameters:
        is_friction = spec.name.startswith(("B_", "b_", "tau_c", "F_c")) or spec.name == "b"
        if is_friction or spec.name == "K_e":
            zero[spec.name] = 0.0
    return {**params.values, **zero}


# --- energy --------------------------------------------------------------------------------

#: Per variant: coordinate -> (viscous, Coulomb) parameter names, and motor coordinate ->
#: (input index, gain). Written out by hand from eq. 2.1-2.4, 3.25-3.26 and 4.17-4.18.
FRICTION = {
    "one-axis": {"phi1": ("B_1", "tau_c1"), "x": ("b", "F_c"), "phi3": ("B_2", "tau_c2")},
    "hframe-20": {
        "x": ("b_bridge", "F_c_bridge"),
        "y": ("b_cart", "F_c_cart"),
        **{f"phi{i}": (f"B_{i}", f"tau_c{i}") for i in range(1, 9)},
    },
    "hframe-8": {
        "x": ("b_bridge", "F_c_bridge"),
        "y": ("b_cart", "F_c_cart"),
        "phi1": ("B_M1", "tau_cM1"),
        "phi2": ("B_M2", "tau_cM2"),
    },
}
MOTORS = {
    "one-axis": {"phi1": (0, "g_1")},
    "hframe-20": {"phi1": (0, "g_1"), "phi2": (1, "g_2")},
    "hframe-8": {"phi1": (0, "g_1"), "phi2": (1, "g_2")},
}


@pytest.mark.parametrize("variant", VARIANTS)
def test_power_balance_at_random_states(variant):
    """dE/dt along the derived dynamics equals the power of the non-conservative forces.

    E = T + V; the expected power is sum_j qdot_j Q_j with Q_j from eq. 2.4 / 3.26 (motor) and
    viscous + tanh-smoothed Coulomb friction. This checks the whole Lagrange derivation, with
    friction, back-EMF and input, at states away from rest (belts stretched, all moving).
    """
    model = build_model(variant)
    values = params_of(variant).values
    # Coulomb levels > 0 so that the smoothed term is exercised too (the files for one-axis and
    # hframe-8 have them; hframe-20's Table 3.1 is linear).
    values = {**values, **{c: 0.01 for _, c in FRICTION[variant].values()}}
    p = model.parameter_vector(values)
    n = len(model.coordinates)
    x = ca.SX.sym("x", model.n_states)
    u = ca.SX.sym("u", model.n_inputs)
    T, V = model.energy(x, p)
    power = ca.Function("power", [x, u], [ca.jacobian(T + V, x) @ model.f(x, u, p)])
    rng = np.random.default_rng(7)
    v_lin, v_ang = model.options.smoothing
    names = [c.name for c in model.coordinates]
    for _ in range(20):
        q = rng.normal(scale=1e-3, size=n)
        qdot = rng.normal(scale=0.05, size=n)
        volts = rng.uniform(-10, 10, size=model.n_inputs)
        expected = 0.0
        for j, name in enumerate(names):
            viscous, coulomb = FRICTION[variant][name]
            v_s = v_lin if model.coordinates[j].unit == "m" else v_ang
            force = -values[viscous] * qdot[j] - values[coulomb] * np.tanh(qdot[j] / v_s)
            if name in MOTORS[variant]:
                k, gain = MOTORS[variant][name]
                kt_r = values["K_t"] / values["R"]
                force += values[gain] * kt_r * volts[k] - kt_r * values["K_e"] * qdot[j]
            expected += force * qdot[j]
        got = float(power(np.r_[q, qdot], volts))
        assert got == pytest.approx(expected, rel=1e-9, abs=1e-12)


# Initial states (q [m or rad], then rates): belts stretched and everything moving.
def _initial_state(model, offset=False, seed=3):
    """Random stretch and velocities; with ``offset`` about a rigid-body displacement by eq. 1.1
    (phi1 = 2 rad, phi2 = -1 rad: x = -29 mm, y = -9.7 mm), where position-dependent stiffness
    differs from the nominal one."""
    n = len(model.coordinates)
    rng = np.random.default_rng(seed)
    scale = np.array([1e-4 if c.unit == "m" else 5e-3 for c in model.coordinates])
    q = rng.normal(size=n) * scale
    if offset:
        q = q + consistent_q(model.variant, 2.0, -1.0)
    return np.r_[q, rng.normal(size=n) * 20 * scale]


def _energy_history(variant, values, options=None, t_end=0.05, offset=False):
    model = build_model(variant, options)
    p = model.parameter_vector(values)
    x = ca.SX.sym("x", model.n_states)
    f = ca.Function("f", [x], [model.f(x, np.zeros(model.n_inputs), p)])
    energy = ca.Function("E", [x], [ca.sum1(ca.vertcat(*model.energy(x, p)))])
    x0 = _initial_state(model, offset)
    # DOP853 at rtol 1e-12: local errors ~1e-12 relative per step over a few hundred steps, so
    # the integrator alone moves E by well under 1e-9 relative (measured: <= 2e-11 for every
    # case of the test below); the test bound is 1e-9, and the smallest physical
    # loss it must catch (friction control below) is > 1e-3.
    sol = solve_ivp(
        lambda _t, s: np.array(f(s)).ravel(),
        (0.0, t_end),
        x0,
        method="DOP853",
        rtol=1e-12,
        atol=1e-14,
        t_eval=np.linspace(0.0, t_end, 101),
    )
    assert sol.success, sol.message
    potential = np.array([float(model.energy(s, p)[1]) for s in sol.y.T])
    total = np.array([float(energy(s)) for s in sol.y.T])
    return total, potential


CASES = [(v, False) for v in VARIANTS] + [("hframe-8", True), ("hframe-20", True)]


@pytest.mark.parametrize(("variant", "position_dependent"), CASES)
def test_energy_conserved_without_friction(variant, position_dependent):
    """No friction, K_e = 0, u = 0: T + V is constant along the derived dynamics.

    With position-dependent stiffness (sec. 4.6) the dynamics are nonlinear but still
    conservative (V depends on q only), so the same must hold.
    """
    values = frictionless(variant)
    options = None
    if position_dependent:
        values = {**values, **LENGTHS[variant]}
        options = ModelOptions(position_dependent_stiffness=True)
    total, potential = _energy_history(variant, values, options, offset=position_dependent)
    # The test has teeth: energy really moves between T and V during the run ...
    assert np.ptp(potential) > 0.2 * total[0]
    # ... and the sum stays put to integrator accuracy (see the tolerance note above).
    assert np.max(np.abs(total - total[0])) <= 1e-9 * total[0]


@pytest.mark.parametrize("variant", VARIANTS)
def test_energy_drops_with_friction(variant):
    """Control for the test above: with the files' viscous friction the energy falls by far
    more than the conservation bound (the bound can fail)."""
    values = {**frictionless(variant)}
    base = params_of(variant).values
    for viscous, _ in FRICTION[variant].values():
        values[viscous] = base[viscous]
    total, _ = _energy_history(variant, values)
    assert total[-1] < (1 - 1e-3) * total[0]


# --- kinematics, eq. 1.1 ---------------------------------------------------------------------

R = 0.0194


def eq_1_1(phi1, phi2, r=R):
    """End-effector displacement from the motor angles, eq. 1.1."""
    return -0.5 * r * phi1 + 0.5 * r * phi2, -0.5 * r * phi1 - 0.5 * r * phi2


def consistent_q(variant, phi1, phi2, r=R, kinematics=eq_1_1):
    """Generalized coordinates with x, y from eq. 1.1 and (hframe-20) idler angles that leave
    every belt section unstretched: sections 1, 2 give phi3 = phi1, phi4 = phi2; 3, 4 give
    phi5 = -phi1 - x/r, phi6 = -phi2 + x/r; 7, 8 give phi7 = phi8 = y/r (eq. 3.13-3.21)."""
    x, y = kinematics(phi1, phi2, r)
    if variant == "hframe-8":
        return np.array([x, y, phi1, phi2])
    idlers = [phi1, phi2, -phi1 - x / r, -phi2 + x / r, y / r, y / r]
    return np.array([x, y, phi1, phi2, *idlers])


@pytest.mark.parametrize("variant", ["hframe-8", "hframe-20"])
def test_eq_1_1_motion_stretches_no_belt(variant):
    model = build_model(variant)
    values = params_of(variant).values
    p = model.parameter_vector(values)
    rng = np.random.default_rng(11)
    for phi1, phi2 in rng.uniform(-30, 30, size=(10, 2)):
        q = consistent_q(variant, phi1, phi2)
        state = np.r_[q, np.zeros_like(q)]
        _, V = model.energy(state, p)
        # V is a sum of k s^2 / 2 with k ~ 1e5 N/m; stretches of 1e-12 m (rounding of x ~ 0.5 m)
        # give ~1e-19 J.
        assert abs(float(V)) < 1e-15
        # At rest no belt pulls: all accelerations vanish (rounding: k * 1e-16 m / 1e-4 kg m^2).
        acc = accelerations(variant, values, q, np.zeros_like(q), np.zeros(2))
        assert np.max(np.abs(acc)) < 1e-6


@pytest.mark.parametrize("variant", ["hframe-8", "hframe-20"])
def test_eq_1_1_with_a_sign_flipped_stretches_belts(variant):
    """Control: the kinematics above is not trivially satisfied (a wrong map stretches belts)."""
    model = build_model(variant)
    p = model.parameter_vector(params_of(variant).values)

    def wrong(phi1, phi2, r):
        x, y = eq_1_1(phi1, phi2, r)
        return -x, y

    q = consistent_q(variant, 1.0, 0.3, kinematics=wrong)
    _, V = model.energy(np.r_[q, np.zeros_like(q)], p)
    assert float(V) > 1.0  # joules: ~1e4 N/m * (1e-2 m)^2


@pytest.mark.parametrize("variant", ["hframe-8", "hframe-20"])
def test_stiffness_null_space_is_eq_1_1(variant):
    """The belt stiffness matrix d2V/dq2 is singular exactly along the eq. 1.1 motions (the two
    rigid-body modes, Table 5.2's double pole at 0)."""
    model = build_model(variant)
    p = model.parameter_vector(params_of(variant).values)
    n = len(model.coordinates)
    x = ca.SX.sym("x", 2 * n)
    stiffness = ca.Function("K", [x], [ca.hessian(model.energy(x, p)[1], x)[0][:n, :n]])
    K = np.array(stiffness(np.zeros(2 * n)))
    eigenvalues, vectors = np.linalg.eigh(K)
    assert np.sum(np.abs(eigenvalues) < 1e-6 * np.max(eigenvalues)) == 2
    null = vectors[:, np.abs(eigenvalues) < 1e-6 * np.max(eigenvalues)]
    rigid = np.column_stack([consistent_q(variant, 1.0, 0.0), consistent_q(variant, 0.0, 1.0)])
    # rigid motions lie in the null space: projecting them out leaves (almost) nothing
    residual = rigid - null @ (null.T @ rigid)
    assert np.max(np.abs(residual)) < 1e-9 * np.max(np.abs(rigid))


# --- one-axis vs eq. 2.1-2.3 and 2.7 -------------------------------------------------------


def test_one_axis_matches_eq_2_1_to_2_4():
    """Eq. 2.1-2.3 (with eq. 2.4 and the amplifier gain g_1 of Fig. 2.21) are printed right."""
    v = params_of("one-axis", tau_c1=0.0, tau_c2=0.0, F_c=0.0).values
    r, k1, k2, k3 = v["r"], v["k1"], v["k2"], v["k3"]
    rng = np.random.default_rng(5)
    for _ in range(10):
        phi1, x, phi3 = rng.normal(scale=[1e-2, 1e-4, 1e-2])
        dphi1, dx, dphi3 = rng.normal(scale=[5.0, 0.1, 5.0])
        volts = rng.uniform(-10, 10)
        tau_m = v["g_1"] * v["K_t"] / v["R"] * volts - v["K_t"] * v["K_e"] / v["R"] * dphi1
        expected = [
            -(phi1 * r - x) * r * k1 / v["J_1"]
            + (phi3 - phi1) * r**2 * k3 / v["J_1"]
            - v["B_1"] / v["J_1"] * dphi1
            + tau_m / v["J_1"],
            (phi1 * r - x) * k1 / v["M"] - (x - phi3 * r) * k2 / v["M"] - v["b"] / v["M"] * dx,
            (x - phi3 * r) * r * k2 / v["J_2"]
            - (phi3 - phi1) * r**2 * k3 / v["J_2"]
            - v["B_2"] / v["J_2"] * dphi3,
        ]
        got = accelerations("one-axis", v, [phi1, x, phi3], [dphi1, dx, dphi3], [volts])
        np.testing.assert_allclose(got, expected, rtol=ROUNDING, atol=1e-9)


def test_one_axis_state_matrix_vs_eq_2_7():
    """Eq. 2.7 against the derived A (thesis state order 2.6: phi1, phi1', x, x', phi3, phi3').

    Typos in the printed 2.7 (eq. 2.1-2.3 themselves are right):
    - a_44 is printed +b/M; eq. 2.2 gives -b/M.
    - a_23 printed k1 r^2/J1, a_41 k1/M, a_45 k2/M, a_63 k2 r^2/J2: the powers of r are off by
      one (eq. 2.1-2.3 give k1 r/J1, k1 r/M, k2 r/M, k2 r/J2; the printed ones also have the
      wrong units, 1/(m s^2) instead of 1/s^2 for a_23).
    - eq. 2.6 itself names x3 = x2', x4 = x2'' where it means x3 = x2, x4 = x2'.
    The rows of 2.7 otherwise agree; b (2.8) is K_t/(R J1) with the amplifier gain 1.
    """
    params = params_of("one-axis", tau_c1=0.0, tau_c2=0.0, F_c=0.0)
    v = params.values
    r, k1, k2, k3, J1, J2, M = (v[n] for n in ("r", "k1", "k2", "k3", "J_1", "J_2", "M"))
    lin = linearize(params)
    order = [0, 3, 1, 4, 2, 5]  # thesis states in our order (q then qdot)
    A = lin.A[np.ix_(order, order)]
    printed = np.array(
        [
            [0, 1, 0, 0, 0, 0],
            [
                -(k1 + k3) * r**2 / J1,
                -v["B_1"] / J1 - v["K_t"] * v["K_e"] / (v["R"] * J1),
                k1 * r**2 / J1,  # typo: k1 r / J1
                0,
                k3 * r**2 / J1,
                0,
            ],
            [0, 0, 0, 1, 0, 0],
            # typos: k1 r / M, -b / M, k2 r / M
            [k1 / M, 0, -(k1 + k2) / M, v["b"] / M, k2 / M, 0],
            [0, 0, 0, 0, 0, 1],
            [k3 * r**2 / J2, 0, k2 * r**2 / J2, 0, -(k2 + k3) * r**2 / J2, -v["B_2"] / J2],
        ]
    )  # a_63 typo: k2 r / J2
    corrected = printed.copy()
    corrected[1, 2] = k1 * r / J1
    corrected[3, 0] = k1 * r / M
    corrected[3, 3] = -v["b"] / M
    corrected[3, 4] = k2 * r / M
    corrected[5, 2] = k2 * r / J2
    np.testing.assert_allclose(A, corrected, rtol=ROUNDING, atol=0)
    typos = {(1, 2), (3, 0), (3, 3), (3, 4), (5, 2)}
    for i, j in np.ndindex(6, 6):
        if (i, j) in typos:
            assert not np.isclose(A[i, j], printed[i, j], rtol=1e-3)
    np.testing.assert_allclose(
        lin.B[order, 0], [0, v["g_1"] * v["K_t"] / (v["R"] * J1), 0, 0, 0, 0], rtol=ROUNDING
    )


# --- hframe-8 vs eq. 4.20-4.32 ---------------------------------------------------------------


def _hframe8_symbols(v):
    return (
        v["r"],
        v["k_l"],
        v["k_r"],
        v["k_b"],
        v["M_bridge"],
        v["M_cart"],
        v["J_M1"],
        v["J_M2"],
    )


def test_hframe8_state_matrix_vs_printed_a_ij():
    """Eq. 4.25's a_ij against the derived A (thesis state order 4.24: x, x', y, y', phi1,
    phi1', phi2, phi2').

    All printed a_ij are right (a_22's "B_bridge" is b_bridge) except one typo:
    - a_45 is printed -b_cart/M_cart; eq. 4.21 (and the energy 4.13) give -k_l r / M_cart.
    The input matrix 4.26 is right (with amplifier gains g_i multiplying it).
    """
    params = params_of("hframe-8", tau_cM1=0.0, tau_cM2=0.0, F_c_cart=0.0, F_c_bridge=0.0)
    v = params.values
    r, kl, kr, kb, Mb, Mc, J1, J2 = _hframe8_symbols(v)
    emf = v["K_t"] * v["K_e"] / v["R"]
    lin = linearize(params)
    order = [0, 4, 1, 5, 2, 6, 3, 7]
    A = lin.A[np.ix_(order, order)]
    a = {
        (2, 1): -(kl + kr + 4 * kb) / Mb,
        (2, 2): -v["b_bridge"] / Mb,
        (2, 3): -(kl - kr) / Mb,
        (2, 5): -(kl + 2 * kb) / Mb * r,
        (2, 7): (kr + 2 * kb) / Mb * r,
        (4, 1): -(kl - kr) / Mc,
        (4, 3): -(kl + kr) / Mc,
        (4, 4): -v["b_cart"] / Mc,
        (4, 5): -v["b_cart"] / Mc,  # typo: -k_l r / M_cart
        (4, 7): -kr / Mc * r,
        (6, 1): -(kl + 2 * kb) / J1 * r,
        (6, 3): -kl / J1 * r,
        (6, 5): -(kl + kb) / J1 * r**2,
        (6, 6): -(v["B_M1"] / J1 + emf / J1),
        (6, 7): kb / J1 * r**2,
        (8, 1): (kr + 2 * kb) / J2 * r,
        (8, 3): -kr / J2 * r,
        (8, 5): kb / J2 * r**2,
        (8, 7): -(kr + kb) / J2 * r**2,
        (8, 8): -(v["B_M2"] / J2 + emf / J2),
    }
    printed = np.zeros((8, 8))
    for i in (1, 3, 5, 7):
        printed[i - 1, i] = 1.0
    for (i, j), value in a.items():
        printed[i - 1, j - 1] = value
    corrected = printed.copy()
    corrected[3, 4] = -kl * r / Mc
    np.testing.assert_allclose(A, corrected, rtol=ROUNDING, atol=0)
    assert not np.isclose(A[3, 4], printed[3, 4], rtol=1e-3)
    expected_B = np.zeros((8, 2))
    expected_B[5, 0] = v["g_1"] * v["K_t"] / (v["R"] * J1)
    expected_B[7, 1] = v["g_2"] * v["K_t"] / (v["R"] * J2)
    np.testing.assert_allclose(lin.B[order], expected_B, rtol=ROUNDING)


def test_hframe8_accelerations_vs_eq_4_20_to_4_32():
    """Eq. 4.20-4.23 and their Simulink form 4.29-4.32 at random states.

    Right as printed: 4.21, 4.22, 4.29, 4.30, 4.31. Typos:
    - 4.20 has no phi1 term and gives phi2 the coefficient -(k_l r + 2 k_b r), which belongs to
      phi1; the phi2 term is +(k_r r + 2 k_b r) phi2 (a_25, a_27 and 4.29 are right). Its y
      coefficient (k_r - k_l) is right.
    - 4.23 prints "- k_r y" for "- k_r r y" (a_83 is right).
    - 4.32 prints "+ r^2 x7" in the k_b bracket for "- r^2 x7" (a_87 is right).
    """
    params = params_of("hframe-8", tau_cM1=0.0, tau_cM2=0.0, F_c_cart=0.0, F_c_bridge=0.0)
    v = params.values
    r, kl, kr, kb, Mb, Mc, J1, J2 = _hframe8_symbols(v)
    kt_r, emf = v["K_t"] / v["R"], v["K_t"] * v["K_e"] / v["R"]
    rng = np.random.default_rng(9)
    for _ in range(10):
        x, y, p1, p2 = rng.normal(scale=[1e-4, 1e-4, 1e-2, 1e-2])
        dx, dy, dp1, dp2 = rng.normal(scale=[0.1, 0.1, 5.0, 5.0])
        u1, u2 = rng.uniform(-10, 10, size=2)
        tau1 = v["g_1"] * kt_r * u1 - emf * dp1
        tau2 = v["g_2"] * kt_r * u2 - emf * dp2
        got = accelerations("hframe-8", v, [x, y, p1, p2], [dx, dy, dp1, dp2], [u1, u2])
        simulink = [  # eq. 4.29-4.32 with F_f = b v, tau_f = B phidot; 4.32 corrected
            ((-x + y + r * p2) * kr + (-x - y - r * p1) * kl)
            + (-4 * x - 2 * r * p1 + 2 * r * p2) * kb
            - v["b_bridge"] * dx,
            (x - y - r * p2) * kr + (-x - y - r * p1) * kl - v["b_cart"] * dy,
            (-r * x - r * y - r**2 * p1) * kl
            + (-2 * r * x - r**2 * p1 + r**2 * p2) * kb
            + tau1
            - v["B_M1"] * dp1,
            (r * x - r * y - r**2 * p2) * kr
            + (2 * r * x + r**2 * p1 - r**2 * p2) * kb  # printed: + r^2 x7
            + tau2
            - v["B_M2"] * dp2,
        ]
        inertia = np.array([Mb, Mc, J1, J2])
        np.testing.assert_allclose(got, np.array(simulink) / inertia, rtol=ROUNDING, atol=1e-9)
        eq_4_21 = (
            -(-kr + kl) * x - (kr + kl) * y - v["b_cart"] * dy - kl * r * p1 - kr * r * p2
        ) / Mc
        eq_4_22 = (
            -(kl + 2 * kb) * r * x
            - kl * r * y
            - (kb + kl) * r**2 * p1
            - (v["B_M1"] + emf) * dp1
            + kb * r**2 * p2
            + v["g_1"] * kt_r * u1
        ) / J1
        assert got[1] == pytest.approx(eq_4_21, rel=ROUNDING)
        assert got[2] == pytest.approx(eq_4_22, rel=ROUNDING)
        eq_4_20_printed = (
            -(kr + kl + 4 * kb) * x
            - v["b_bridge"] * dx
            + (kr - kl) * y
            - (kl * r + 2 * kb * r) * p2
        ) / Mb
        eq_4_20_fixed = (
            eq_4_20_printed
            + ((kl * r + 2 * kb * r) * p2 - (kl * r + 2 * kb * r) * p1 + (kr * r + 2 * kb * r) * p2)
            / Mb
        )
        assert got[0] == pytest.approx(eq_4_20_fixed, rel=ROUNDING)
        assert got[0] != pytest.approx(eq_4_20_printed, rel=1e-3)
        eq_4_23_printed = (
            (kr + 2 * kb) * r * x
            - kr * y
            + kb * r**2 * p1
            - (kb + kr) * r**2 * p2
            - (v["B_M2"] + emf) * dp2
            + v["g_2"] * kt_r * u2
        ) / J2
        eq_4_23_fixed = eq_4_23_printed + (kr * y - kr * r * y) / J2
        assert got[3] == pytest.approx(eq_4_23_fixed, rel=ROUNDING)
        assert got[3] != pytest.approx(eq_4_23_printed, rel=1e-3)


# --- hframe-20 vs eq. 3.27-3.36 --------------------------------------------------------------


def test_hframe20_accelerations_vs_eq_3_27_to_3_36():
    """Eq. 3.27-3.36 (linear: no Coulomb) at random states.

    Right as printed: 3.28, 3.29, 3.31-3.36. Typos:
    - 3.27 prints "- k_3 r phi6" where the energies 3.15-3.16 give "- k_3 r phi5 + k_4 r phi6";
    - 3.30 prints "- k_4 r x" for "+ k_4 r x" (3.16: d/dphi2 of k_4 (phi2 r + phi6 r - x)^2 / 2).
    The bridge pulleys' masses m_p5..m_p8 of eq. 3.9-3.12 are part of M_bridge.
    """
    params = params_of("hframe-20")
    v = params.values
    r = v["r"]
    k = {i: v[f"k_{i}"] for i in range(1, 10)}
    J = {i: v[f"J_{i}"] for i in range(1, 9)}
    B = {i: v[f"B_{i}"] for i in range(1, 9)}
    kt_r, emf = v["K_t"] / v["R"], v["K_t"] * v["K_e"] / v["R"]
    rng = np.random.default_rng(13)
    for _ in range(10):
        q = rng.normal(scale=[1e-4, 1e-4, *[1e-2] * 8])
        qd = rng.normal(scale=[0.1, 0.1, *[5.0] * 8])
        u1, u2 = rng.uniform(-10, 10, size=2)
        x, y, dx, dy = q[0], q[1], qd[0], qd[1]
        ph = {i: q[1 + i] for i in range(1, 9)}
        dph = {i: qd[1 + i] for i in range(1, 9)}
        got = accelerations("hframe-20", v, q, qd, [u1, u2])
        eq_3_27 = (
            -(k[3] + k[4] + k[5] + k[6]) * x
            - v["b_bridge"] * dx
            - k[3] * r * ph[1]
            + k[4] * r * ph[2]
            - k[5] * r * ph[3]
            + k[6] * r * ph[4]
            - k[3] * r * ph[6]  # printed; derived: - k3 r phi5 + k4 r phi6
            - k[5] * r * ph[7]
            + k[6] * r * ph[8]
        ) / v["M_bridge"]
        fix_3_27 = (k[3] * r * ph[6] - k[3] * r * ph[5] + k[4] * r * ph[6]) / v["M_bridge"]
        eq_3_30 = (
            -k[4] * r * x  # printed; derived: + k4 r x
            - (k[2] + k[4]) * r**2 * ph[2]
            - (B[2] + emf) * dph[2]
            + k[2] * r**2 * ph[4]
            - k[4] * r**2 * ph[6]
            + v["g_2"] * kt_r * u2
        ) / J[2]
        fix_3_30 = 2 * k[4] * r * x / J[2]
        right = [
            (-(k[7] + k[8]) * y - v["b_cart"] * dy + k[7] * r * ph[7] + k[8] * r * ph[8])
            / v["M_cart"],
            (
                -k[3] * r * x
                - (k[1] + k[3]) * r**2 * ph[1]
                - (B[1] + emf) * dph[1]
                + k[1] * r**2 * ph[3]
                - k[3] * r**2 * ph[5]
                + v["g_1"] * kt_r * u1
            )
            / J[1],
            None,  # 3.30
            (
                -k[5] * r * x
                + k[1] * r**2 * ph[1]
                - (k[1] + k[5]) * r**2 * ph[3]
                - B[3] * dph[3]
                - k[5] * r**2 * ph[7]
            )
            / J[3],
            (
                k[6] * r * x
                + k[2] * r**2 * ph[2]
                - (k[2] + k[6]) * r**2 * ph[4]
                - B[4] * dph[4]
                - k[6] * r**2 * ph[8]
            )
            / J[4],
            (
                -k[3] * r * x
                - k[3] * r**2 * ph[1]
                - (k[3] + k[9]) * r**2 * ph[5]
                - B[5] * dph[5]
                + k[9] * r**2 * ph[6]
            )
            / J[5],
            (
                k[4] * r * x
                - k[4] * r**2 * ph[2]
                + k[9] * r**2 * ph[5]
                - (k[4] + k[9]) * r**2 * ph[6]
                - B[6] * dph[6]
            )
            / J[6],
            (
                -k[5] * r * x
                + k[7] * r * y
                - k[5] * r**2 * ph[3]
                - (k[5] + k[7]) * r**2 * ph[7]
                - B[7] * dph[7]
            )
            / J[7],
            (
                k[6] * r * x
                + k[8] * r * y
                - k[6] * r**2 * ph[4]
                - (k[6] + k[8]) * r**2 * ph[8]
                - B[8] * dph[8]
            )
            / J[8],
        ]
        for j, expected in enumerate(right, start=1):
            if expected is not None:
                assert got[j] == pytest.approx(expected, rel=ROUNDING, abs=1e-9), j
        assert got[0] == pytest.approx(eq_3_27 + fix_3_27, rel=ROUNDING)
        assert got[0] != pytest.approx(eq_3_27, rel=1e-3)
        assert got[3] == pytest.approx(eq_3_30 + fix_3_30, rel=ROUNDING)
        assert got[3] != pytest.approx(eq_3_30, rel=1e-3)


# --- model options ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs",
    [
        {"smoothing_linear_m_per_s": 0.0},
        {"smoothing_linear_m_per_s": -1e-3},
        {"smoothing_angular_rad_per_s": float("nan")},
        {"smoothing_angular_rad_per_s": float("inf")},
        {"smoothing_linear_m_per_s": "1e-3"},
    ],
)
def test_smoothing_option_is_validated(kwargs):
    name = next(iter(kwargs))
    with pytest.raises(ModelError, match=name):
        ModelOptions(**kwargs)


def test_smoothing_velocity_sets_the_coulomb_law():
    """F_c tanh(v / v_s): at v = v_s the Coulomb force is F_c tanh(1) (hframe-8, cart)."""
    options = ModelOptions(smoothing_linear_m_per_s=0.02)
    v = params_of("hframe-8").values
    v_s = 0.02
    got = accelerations("hframe-8", v, np.zeros(4), [0, v_s, 0, 0], [0, 0], options)
    expected = -(v["b_cart"] * v_s + v["F_c_cart"] * np.tanh(1.0)) / v["M_cart"]
    assert got[1] == pytest.approx(expected, rel=ROUNDING)


def test_one_axis_has_no_position_dependent_stiffness():
    with pytest.raises(ModelError, match="only available for H-frame"):
        build_model("one-axis", ModelOptions(position_dependent_stiffness=True))


#: Belt lengths at the origin [m] (the thesis gives none; these are plausible for the rig).
LENGTHS = {
    "hframe-8": {"l_l0": 1.9, "l_r0": 2.2, "l_b0": 1.4},
    "hframe-20": {"l_3": 0.35, "l_4": 0.4, "l_5": 0.45, "l_6": 0.5, "l_7": 0.3, "l_8": 0.33},
}
PD = ModelOptions(position_dependent_stiffness=True)


def with_lengths(params):
    """The parameter set plus the optional belt lengths of section 4.6."""
    values = {**params.values, **LENGTHS[params.variant]}
    return ParameterSet(params.variant, values, params.title, params.source)


@pytest.mark.parametrize("variant", ["hframe-8", "hframe-20"])
def test_position_dependent_stiffness_is_nominal_at_the_origin(variant):
    """With k = AE / l(x, y), at x = y = 0 every belt has its nominal stiffness: the same V for
    any stretch, and the same linearization about rest as the constant-stiffness model."""
    params = with_lengths(params_of(variant))
    constant, dependent = build_model(variant), build_model(variant, PD)
    p_c = constant.parameter_vector(params.values)
    p_d = dependent.parameter_vector(params.values)
    n = len(constant.coordinates)
    rng = np.random.default_rng(17)
    state = np.r_[0.0, 0.0, rng.normal(scale=1e-2, size=n - 2), np.zeros(n)]
    assert float(dependent.energy(state, p_d)[1]) == pytest.approx(
        float(constant.energy(state, p_c)[1]), rel=ROUNDING
    )
    lin_c = linearize(params, constant)
    lin_d = linearize(params, dependent)
    np.testing.assert_allclose(lin_d.A, lin_c.A, rtol=ROUNDING, atol=1e-6)
    np.testing.assert_array_equal(lin_d.B, lin_c.B)


def test_position_dependent_stiffness_follows_eq_4_39_to_4_41():
    """Away from the origin each spring is k0 l0 / (l0 + dl): eq. 4.39-4.41 with AE = k0 l0."""
    params = with_lengths(params_of("hframe-8"))
    v = params.values
    model = build_model("hframe-8", PD)
    x, y, p1, p2 = 0.05, -0.03, 0.2, -0.1
    r = v["r"]
    stretches = {"l": p1 * r + x + y, "r": -p2 * r + x - y, "b": -p1 * r + p2 * r - 2 * x}
    changes = {"l": x + y, "r": x - y, "b": -2 * x}
    expected = sum(
        0.5 * v[f"k_{s}"] * v[f"l_{s}0"] / (v[f"l_{s}0"] + changes[s]) * stretches[s] ** 2
        for s in "lrb"
    )
    state = np.r_[x, y, p1, p2, np.zeros(4)]
    assert float(model.energy(state, model.parameter_vector(v))[1]) == pytest.approx(
        expected, rel=ROUNDING
    )
    # and it is not the constant-stiffness energy there (the option does something)
    constant = build_model("hframe-8")
    assert float(constant.energy(state, constant.parameter_vector(v))[1]) != pytest.approx(
        expected, rel=1e-3
    )


@pytest.mark.parametrize("variant", ["hframe-8", "hframe-20"])
def test_position_dependent_stiffness_without_lengths_is_a_clear_error(variant):
    params = params_of(variant)
    missing = sorted(LENGTHS[variant])
    with pytest.raises(ModelError, match="missing parameter") as info:
        linearize(params, build_model(variant, PD))
    for name in missing:
        assert name in str(info.value)
