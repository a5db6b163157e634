"""Fit problems (``fitting.problem``) are checked before any solving: names, bounds, data, rigs;
parameters in theta and back; which parameters get a prior; which records start at rest."""

import dataclasses
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from hframe_id.errors import FitError
from hframe_id.fitting import FitOptions
from hframe_id.fitting.dataset import starts_at_rest
from hframe_id.fitting.experiment import default_channel_std
from hframe_id.fitting.problem import build_problem, default_free
from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording

MODELS = Path(__file__).resolve().parents[2] / "models"


#: A small free set (stiffness, mass, viscous and Coulomb friction).
FREE = ("k_l", "k_r", "M_cart", "b_cart", "F_c_cart")


@pytest.fixture(scope="module")
def step(table, x_step):
    """A 4 V x-motion step from rest (50 samples of pre-roll)."""
    return x_step(table, seed=7)


def test_default_free_set_is_the_issues(table):
    free = default_free(build_model("hframe-8"))
    assert set(free) == {
        "k_l", "k_r", "k_b", "J_M1", "J_M2", "M_cart", "M_bridge", "B_M1", "B_M2",
        "b_cart", "b_bridge", "tau_cM1", "tau_cM2", "F_c_cart", "F_c_bridge", "g_2",
    }  # fmt: skip
    one_axis = default_free(build_model("one-axis"))
    assert "g_1" not in one_axis and "r" not in one_axis and "K_t" not in one_axis


def test_unknown_free_parameter_suggests_the_nearest(table, recording):
    with pytest.raises(FitError, match=r"'k_q'.*did you mean 'k_l'|'k_q'.*did you mean"):
        build_problem([recording], table, FitOptions(free=("k_q",)))
    with pytest.raises(FitError, match="J_m1.*did you mean 'J_M1'"):
        build_problem([recording], table, FitOptions(fix=("J_m1",)))


def test_theta_of_inverts_parameters(table, recording):
    """theta -> parameters -> theta is the identity (log scale and linear alike), to rounding."""
    problem = build_problem([recording], table, FitOptions(free=("k_l", "B_M1", "g_2")))
    theta = np.array([0.3, -0.8, 0.05])
    values = dict(zip(problem.model.parameter_names, problem.parameters(theta), strict=True))
    assert np.allclose(problem.theta_of(table.replace_values(**values)), theta, atol=1e-12)


def test_patterns_select_parameters(table, recording):
    problem = build_problem([recording], table, FitOptions(free=("k_*",), fix=("k_b",)))
    assert problem.free_names == ("k_l", "k_r")


def test_default_names_the_default_free_set_among_others(table, recording):
    """``"default"`` in the free set is the declaration's default set (here with g_1, which
    it holds), minus ``fix`` as ever; unknown names beside it still fail."""
    problem = build_problem([recording], table, FitOptions(free=("default", "g_1"), fix=("k_b",)))
    expected = [n for n in default_free(problem.model) if n != "k_b"] + ["g_1"]
    assert list(problem.free_names) == expected
    with pytest.raises(FitError, match="'g_3'"):
        build_problem([recording], table, FitOptions(free=("default", "g_3")))


def test_bounds_excluding_the_initial_value_fail_before_solving(table, recording):
    with pytest.raises(FitError, match=r"bounds for k_l \[1, 2\] exclude its initial value"):
        build_problem([recording], table, FitOptions(bounds={"k_l": (1.0, 2.0)}))
    with pytest.raises(FitError, match="not free"):
        build_problem([recording], table, FitOptions(free=("k_r",), bounds={"k_l": (1, 2e5)}))


def test_friction_reaches_zero_where_asked_or_started_there(table, recording):
    """Friction (nonnegative) is fitted in log scale, and linearly from 0 where named in
    zero_reachable or started at 0 (Table 4.1's Coulomb terms): its default box then starts
    at 0, which is physics, not the box."""
    zero = table.replace_values(F_c_cart=0.0)
    options = FitOptions(free=("F_c_cart", "b_cart", "B_M1", "k_l"), zero_reachable=("b_cart",))
    problem = build_problem([recording], zero, options)
    assert problem.linear.tolist() == [True, True, False, False]
    p = problem.parameters(problem.theta_lower)
    names = problem.model.parameter_names
    assert p[names.index("F_c_cart")] == 0.0 and p[names.index("b_cart")] == 0.0
    assert p[names.index("B_M1")] == pytest.approx(table.values["B_M1"] / 10)
    assert p[names.index("k_l")] == pytest.approx(table.values["k_l"] / 10)
    assert problem.zero_floor.tolist() == [True, True, False, False]
    assert problem.box_lower.tolist() == [False, False, True, True]
    assert problem.on_box(problem.theta_upper).all()
    assert not problem.on_box(problem.theta_lower)[:2].any()
    with pytest.raises(FitError, match="zero_reachable: k_l is not a nonnegative"):
        build_problem([recording], table, FitOptions(zero_reachable=("k_l",)))


def test_mixed_variants_and_rigs_are_refused(table, recording):
    one_axis = load_parameter_file(MODELS / "one-axis-table2.3.yaml")
    other = simulate_recording(one_axis, np.full((300, 1), 5.0), seed=2)
    with pytest.raises(FitError, match="different model variants"):
        build_problem([recording, other], table, FitOptions())
    rig = dict(recording.rig, encoder_counts_per_rev=1000)
    coarse = dataclasses.replace(recording, rig=rig)
    with pytest.raises(FitError, match="different rigs.*encoder_counts_per_rev"):
        build_problem([recording, coarse], table, FitOptions())
    with pytest.raises(FitError, match="initial parameters are for one-axis"):
        build_problem([recording], one_axis, FitOptions())


def test_too_few_valid_samples_are_refused(table, recording):
    valid = recording.valid.copy()
    valid[:] = False
    valid[:9] = True
    sparse = dataclasses.replace(recording, valid=valid)
    with pytest.raises(FitError, match="only 36 valid output samples"):
        build_problem([sparse], table, FitOptions())


def test_invalid_samples_are_left_out(table, recording):
    outputs = recording.outputs.copy()
    valid = recording.valid.copy()
    outputs[100:120, 2] = 1e3  # a laser holding garbage, flagged invalid
    valid[100:120, 2] = False
    flagged = dataclasses.replace(recording, outputs=outputs, valid=valid)
    problem = build_problem([flagged], table, FitOptions())
    exp = problem.experiments[0]
    assert not exp.valid[100:120, 2].any() and np.isnan(exp.measured[100:120, 2]).all()


def test_weights_default_to_the_sensor_noise(table, recording):
    problem = build_problem([recording], table, FitOptions())
    step = 2 * math.pi / 321084
    assert problem.channel_std[:2] == pytest.approx([step / math.sqrt(12)] * 2, rel=1e-12)
    assert problem.channel_std[2:] == pytest.approx([5e-6, 5e-6], rel=1e-12)
    assert problem.quantization[:2] == pytest.approx([step, step], rel=1e-12)


def test_each_recording_is_weighed_by_its_own_levels_where_given(table, recording):
    """``recording_std`` gives x one level per recording; phi1, phi2 and y keep the sensors'
    (or ``channel_std``); the transcription divides each window's residuals by its own."""
    from hframe_id.fitting.shooting import MultipleShooting

    options = FitOptions(channel_std={"y": 1e-4}, recording_std={"x": (1e-3, 4e-3)})
    problem = build_problem([recording, recording], table, options)
    sensors = build_problem([recording], table, FitOptions()).channel_std
    expected = np.tile([sensors[0], sensors[1], 0.0, 1e-4], (2, 1))
    expected[:, 2] = (1e-3, 4e-3)
    assert problem.recording_std == pytest.approx(expected, rel=1e-12)
    ms = MultipleShooting(
        problem, transcription=options.for_model("hframe-8").transcription_options
    )
    second = ms.window_experiment == 1
    assert np.all(ms.weight[second][..., 2][ms.weight[second][..., 2] > 0] == 1 / 4e-3)
    assert np.all(ms.weight[~second][..., 2][ms.weight[~second][..., 2] > 0] == 1 / 1e-3)


def test_recording_levels_must_match_the_recordings(table, recording):
    with pytest.raises(FitError, match=r"recording_std\['x'\]: 3 values for 2 recordings"):
        build_problem([recording, recording], table, FitOptions(recording_std={"x": (1, 2, 3)}))
    with pytest.raises(FitError, match="recording_std: unknown output 'z'"):
        build_problem([recording], table, FitOptions(recording_std={"z": (1.0,)}))


def test_theta_of_a_linear_parameter_starting_at_zero_warns_nothing(table, recording):
    """F_c_cart fitted linearly from 0 and at 0 (a reference file with it at 0): theta_of
    computes 0 / 0 for the unused log."""
    start = table.replace_values(F_c_cart=0.0)
    problem = build_problem([recording], start, FitOptions(free=("k_l", "F_c_cart")))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        theta = problem.theta_of(start)
    np.testing.assert_array_equal(theta, 0.0)


def test_rest_is_told_from_motion_by_the_first_window(table, step, in_motion):
    problem = build_problem([step, in_motion(step, 150)], table, FitOptions(free=FREE))
    model = problem.model
    std = _sensor_std(step, model)
    at_rest, moving = problem.experiments
    assert starts_at_rest(at_rest.measured, at_rest.valid, std, 10, 1e-3)
    assert not starts_at_rest(moving.measured, moving.valid, std, 10, 1e-3)
    assert at_rest.at_rest and not moving.at_rest


def test_the_prior_method_frees_the_held_idler_with_its_weight(one_axis):
    table, rec = one_axis
    held = build_problem([rec], table, FitOptions())
    assert not set(IDLER) & set(held.free_names) and not held.prior_names
    problem = build_problem([rec], table, FitOptions(consider_method="prior"))
    # Freed in model order, each with weight 1 / 0.2 (the default +/-20 %) around its start.
    assert problem.free_names == tuple(
        n for n in problem.model.parameter_names if n in held.free_names or n in IDLER
    )
    assert problem.prior_names == IDLER
    weights = dict(zip(problem.free_names, problem.prior_weight, strict=True))
    assert [weights[n] for n in IDLER] == pytest.approx([5.0, 5.0, 5.0])
    # Explicit priors replace the default; a fixed parameter keeps no prior (held exact).
    chosen = build_problem([rec], table, FitOptions(consider_method="prior", consider={"J_2": 0.1}))
    assert chosen.prior_names == ("J_2",) and "B_2" not in chosen.free_names
    fixed = build_problem([rec], table, FitOptions(consider_method="prior", fix=("J_2",)))
    assert fixed.prior_names == ("B_2", "tau_c2") and "J_2" not in fixed.free_names


IDLER = ("J_2", "B_2", "tau_c2")


@pytest.fixture(scope="module")
def one_axis():
    table = load_parameter_file(MODELS / "one-axis-table2.3.yaml")
    u = np.zeros((300, 1))
    u[50:200] = 5.0
    return table, simulate_recording(table, u, seed=3)


def _sensor_std(recording, model):
    return np.array([default_channel_std(recording, s.name) for s in model.outputs])


def test_the_problem_keeps_its_own_options_and_the_transcription_gets_its_own(table, recording):
    """Each link owns its options: the problem the ``problem_options`` (no solver or strategy
    settings), the transcription the ``transcription_options`` it is given (by default the
    model's, as ``FitOptions()`` resolves them)."""
    from hframe_id.fitting.shooting import MultipleShooting

    options = FitOptions(bound_factor=3.0, shooting_interval=25, max_iterations=7)
    problem = build_problem([recording], table, options)
    resolved = options.for_model(table.variant)
    assert problem.problem_options == resolved.problem_options
    assert not hasattr(problem, "options")
    given = MultipleShooting(problem, transcription=resolved.transcription_options)
    assert given.transcription == resolved.transcription_options and given.m == 25
    default = FitOptions().for_model(table.variant).transcription_options
    assert MultipleShooting(problem).transcription == default


def test_a_problems_parameter_set_holds_theta_and_the_fixed_values(table, steps):
    """``FitProblem.parameter_set``: the start's set with the free parameters at theta's
    values (SI) and the fixed ones bit for bit."""
    from hframe_id.fitting import FitOptions
    from hframe_id.fitting.problem import build_problem

    problem = build_problem(steps, table, FitOptions(free=("k_l", "M_cart")))
    theta = np.array([np.log(2.0), 0.0])
    params = problem.parameter_set(theta)
    assert params.values["k_l"] == pytest.approx(2 * table.values["k_l"], rel=1e-15)
    assert params.values["M_cart"] == table.values["M_cart"]
    assert {n: v for n, v in params.values.items() if n not in ("k_l", "M_cart")} == {
        n: v for n, v in table.values.items() if n not in ("k_l", "M_cart")
    }
    assert params.variant == table.variant
