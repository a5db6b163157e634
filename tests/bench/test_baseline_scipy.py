"""The SciPy single-shooting baseline: recovery on a short synthetic problem, bad input."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from bench.baseline_scipy import (
    BaselineOptions,
    default_free_names,
    fit_single_shooting,
)
from hframe_id.errors import FitError, OptionError
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording

MODELS = Path(__file__).resolve().parents[2] / "models"


def steps(v1: float, v2: float, n: int = 300) -> np.ndarray:
    """50 ms at rest, a 0.2 s voltage step, 50 ms coasting (1 kHz)."""
    u = np.zeros((n, 2))
    u[50:250] = (v1, v2)
    return u


@pytest.fixture(scope="module")
def truth():
    return load_parameter_file(MODELS / "hframe-8-table4.2.yaml")


@pytest.fixture(scope="module")
def recordings(truth):
    # One y-motion and one x-motion experiment (both motors, both lasers move), 0.3 s each.
    return [
        simulate_recording(truth, steps(-4, -4), seed=11),
        simulate_recording(truth, steps(-4, 4), seed=12),
    ]


@pytest.fixture(scope="module")
def start(truth):
    """Every free parameter off by a random factor in [1/1.3, 1.3] (seeded)."""
    names = default_free_names("hframe-8")
    factors = np.exp(np.random.default_rng(5).uniform(-np.log(1.3), np.log(1.3), len(names)))
    return truth.replace_values(
        **{n: truth.values[n] * f for n, f in zip(names, factors, strict=True)}
    )


@pytest.fixture(scope="module")
def fitted(recordings, start):
    return fit_single_shooting(recordings, start)


def test_default_free_set_is_the_fitters():
    assert default_free_names("hframe-8") == (
        "k_l", "k_r", "k_b", "J_M1", "J_M2", "M_cart", "M_bridge", "B_M1", "B_M2",
        "b_cart", "b_bridge", "tau_cM1", "tau_cM2", "F_c_cart", "F_c_bridge", "g_2",
    )  # fmt: skip


def test_recovers_truth_from_a_modest_start(fitted, truth, recordings):
    assert fitted.success, fitted.message
    assert not fitted.capped and fitted.at_bound == ()
    # 1 % is the recovery tolerance. On these 0.6 s of data the noise-limited
    # optimum itself lies within 0.35 % of the truth (worst: the cart's Coulomb force, which
    # two 0.2 s steps barely excite; everything else within 0.05 %), and the solver stops at
    # relative changes of 1e-8, so 1 % leaves a 3x margin without hiding a wrong optimum.
    for name in default_free_names("hframe-8"):
        assert fitted.estimates[name] == pytest.approx(truth.values[name], rel=0.01), name
    # The optimum, not merely a point near the truth: no worse than the truth's own cost.
    at_truth = fit_single_shooting(recordings, truth, options=BaselineOptions(max_nfev=1))
    assert fitted.cost <= at_truth.initial_cost * (1 + 1e-6)
    # Weighted residuals are O(1): 1/2 sum r^2 is about 1/2 n (quantization bias adds a bit).
    assert fitted.cost < fitted.n_residuals
    assert fitted.parameters.values["r"] == truth.values["r"]  # fixed ones untouched


def test_finite_differences_reach_the_same_optimum(recordings, start, fitted):
    options = BaselineOptions(jacobian="finite-differences")
    result = fit_single_shooting(recordings, start, options=options)
    assert result.success, result.message
    assert result.jacobian == "finite-differences"
    # Same cost function, so the same optimum to well within the 1e-8 solver tolerances'
    # reach on the weakly determined splits (forward-difference Jacobian errors ~1e-6).
    for name, value in fitted.estimates.items():
        assert result.estimates[name] == pytest.approx(value, rel=1e-4), name


def test_a_capped_fit_is_not_converged(recordings, start):
    capped = fit_single_shooting(recordings, start, options=BaselineOptions(max_nfev=2))
    assert capped.capped and not capped.success
    timed = fit_single_shooting(recordings, start, options=BaselineOptions(max_time_s=1e-3))
    assert timed.capped and not timed.success
    assert "time limit" in timed.message
    assert timed.cost <= timed.initial_cost


def test_free_subset_keeps_the_rest_fixed(recordings, truth):
    start = truth.replace_values(k_l=truth.values["k_l"] * 1.2)
    result = fit_single_shooting(recordings, start, ["k_l"])
    assert result.success, result.message
    assert set(result.estimates) == {"k_l"}
    assert result.estimates["k_l"] == pytest.approx(truth.values["k_l"], rel=0.01)


def test_bad_input_is_a_clear_error(recordings, truth):
    with pytest.raises(FitError, match="no recordings"):
        fit_single_shooting([], truth)
    with pytest.raises(FitError, match="did you mean 'k_l'"):
        fit_single_shooting(recordings, truth, ["k_ll"])
    with pytest.raises(FitError, match="twice"):
        fit_single_shooting(recordings, truth, ["k_l", "k_l"])
    with pytest.raises(FitError, match="no free parameters"):
        fit_single_shooting(recordings, truth, [])
    with pytest.raises(FitError, match="F_c_cart starts at 0.0"):
        fit_single_shooting(recordings, truth.replace_values(F_c_cart=0.0), ["F_c_cart"])
    one_axis = load_parameter_file(MODELS / "one-axis-table2.3.yaml")
    single = simulate_recording(one_axis, np.zeros((20, 1)))
    with pytest.raises(FitError, match="recording of 'one-axis'"):
        fit_single_shooting([recordings[0], single], truth)
    no_laser = dataclasses.replace(
        recordings[0], rig={k: v for k, v in recordings[0].rig.items() if k != "laser_noise_std_m"}
    )
    with pytest.raises(FitError, match="laser_noise_std_m"):
        fit_single_shooting([no_laser], truth)
    # The recording is read on the model's channels (its Dataset): a missing output is
    # refused, not fitted without.
    no_y = dataclasses.replace(
        recordings[0],
        outputs=recordings[0].outputs[:, :3],
        valid=recordings[0].valid[:, :3],
        output_names=recordings[0].output_names[:3],
    )
    with pytest.raises(FitError, match="no output 'y'"):
        fit_single_shooting([no_y], truth)
    jittered = dataclasses.replace(recordings[0], time_s=recordings[0].time_s * 1.01)
    with pytest.raises(FitError, match="sample period|uniformly"):
        fit_single_shooting([jittered], truth)


@pytest.mark.parametrize(
    "changes, match",
    [
        ({"jacobian": "exact"}, "jacobian"),
        ({"bound_factor": 1.0}, "bound_factor"),
        ({"fd_step": 0.0}, "fd_step"),
        ({"max_nfev": 0}, "max_nfev"),
        ({"max_time_s": -1.0}, "max_time_s"),
        ({"x_scale": "auto"}, "x_scale"),
        ({"tr_solver": "svd"}, "tr_solver"),
        ({"rest_state": "moving"}, "rest_state"),
        ({"n_threads": 0}, "n_threads"),
    ],
)
def test_options_validate(changes, match):
    with pytest.raises(OptionError, match=match):
        BaselineOptions(**changes)
