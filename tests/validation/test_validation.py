"""Validation (compare / resid / k-step prediction / leave-one-out) on seeded synthetic data."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hframe_id.errors import FitError, OptionError
from hframe_id.fitting import FitOptions
from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.recording import Recording
from hframe_id.recordings.sensors import SensorModel
from hframe_id.recordings.simulated import simulate_recording
from hframe_id.simulation.open_loop import simulate
from hframe_id.validation import ValidationOptions, fit_percent, validate
from hframe_id.validation.checks import check_inputs
from hframe_id.validation.cross_validation import leave_one_out
from hframe_id.validation.residuals import autocorrelation, band_99, cross_correlation

ROOT = Path(__file__).resolve().parents[2]
TABLE = load_parameter_file(ROOT / "models" / "hframe-8-table4.2.yaml")
#: White measurement noise of the synthetic records [rad for encoders, m for lasers].
NOISE_STD = {"phi1": 1e-5, "phi2": 1e-5, "x": 5e-6, "y": 5e-6}


def _steps(v1: float, v2: float, n: int = 400, start: int = 50) -> np.ndarray:
    u = np.zeros((n, 2))
    u[start:] = (v1, v2)
    return u


def noisy_recording(params, volts, seed: int, name: str = "noisy.mcap") -> Recording:
    """A record whose only error is seeded white Gaussian noise (no quantization, no DAC
    rounding: the commands are multiples of the DAC step), from rest at the origin."""
    sensors = SensorModel()
    model = build_model(params.variant)
    applied = sensors.dac(volts)
    states = simulate(model, model.parameter_vector(params.values), applied, 1e-3)[:-1]
    clean = np.array(model.output.map(states.shape[0])(states.T)).T
    names = tuple(s.name for s in model.outputs)
    std = np.array([NOISE_STD[n] for n in names])
    noise = np.random.default_rng(seed).standard_normal(clean.shape) * std
    return Recording(
        variant=params.variant,
        sample_period_s=1e-3,
        time_s=np.arange(len(volts)) * 1e-3,
        inputs=applied,
        input_names=("u1", "u2"),
        outputs=clean + noise,
        output_names=names,
        valid=np.ones(clean.shape, dtype=bool),
        rig={"serial_number": "synthetic", **sensors.as_metadata()},
        path=Path(name),
    )


@pytest.fixture(scope="module")
def diagonal():
    # unequal voltages move both motors and both axes, so every channel varies and its fit
    # [%] is meaningful (below ~1.5 V a motor does not overcome its Coulomb torque: its
    # angle barely moves and its fit is ~96 % on noise alone)
    return noisy_recording(TABLE, _steps(-4.0, 2.5), seed=1)


def test_fit_percent_matches_matlab_definition():
    y = np.array([0.0, 1.0, 2.0, 3.0])
    valid = np.ones(4, dtype=bool)
    assert fit_percent(y, y, valid) == 100.0
    assert fit_percent(y, np.full(4, y.mean()), valid) == 0.0
    # |y - y_hat| = |y - mean| / 2 -> 50 %
    assert fit_percent(y, y + (y - y.mean()) / 2, valid) == pytest.approx(50.0)
    assert np.isnan(fit_percent(np.ones(4), np.ones(4), valid))  # no variation: undefined
    # invalid samples are ignored, whatever they hold
    assert fit_percent(np.r_[y, 1e9], np.r_[y, 0.0], np.r_[valid, False]) == 100.0


def test_perfect_model_fits_about_100_percent_with_white_residuals(diagonal):
    result = validate([TABLE], [diagonal], ValidationOptions(horizon=0))
    (run,) = result.recordings[0].runs
    for ch in run.channels:
        # noise std / signal std is below 1e-3 on every channel here (mm and 0.1 rad motions)
        assert ch.simulation_fit_percent > 99.0, ch.name
        # the residual is the seeded white noise plus a constant: the simulation starts at
        # the first sample's (noisy) positions, an offset of about one noise std, so the rms
        # is between 1 and ~sqrt(2) noise std (+10 %: the rms of N = 400 draws varies by 3.5 %)
        assert NOISE_STD[ch.name] * 0.9 < ch.residual_rms < NOISE_STD[ch.name] * 1.6
        # each test wrongly fails white noise in at most 1 % of cases; the seed is fixed
        assert ch.autocorrelation.passes, ch.name
        assert ch.independent, ch.name


def test_a_wrong_parameter_lowers_the_fit_and_fails_resid(diagonal):
    wrong = TABLE.replace_values(b_cart=TABLE.values["b_cart"] * 1.5)
    result = validate([TABLE, wrong], [diagonal], ValidationOptions(horizon=0))
    good, bad = result.recordings[0].runs
    for g, b in zip(good.channels, bad.channels, strict=True):
        assert b.simulation_fit_percent < g.simulation_fit_percent, g.name
    # the cart (y) and motors respond to b_cart: their residuals are far from white
    assert not all(ch.passes for ch in bad.channels)


def test_99_percent_band_holds_for_white_sequences():
    # 400 seeded white sequences of N = 1000 with an independent white input: each
    # normalized correlation at a lag != 0 is ~N(0, 1/N), so 1 % of them fall outside
    # +/- 2.58 / sqrt(N). 400 x 25 values: the count outside is binomial (mean 100, std 10);
    # 0.6-1.4 % is +/- 4 std (lags of one sequence are nearly independent for white data).
    rng = np.random.default_rng(7)
    n, lags, trials = 1000, 25, 400
    valid = np.ones(n, dtype=bool)
    outside_auto = outside_cross = passed = 0
    for _ in range(trials):
        e, u = rng.standard_normal(n), rng.standard_normal(n)
        auto = autocorrelation(e, valid, lags)
        cross = cross_correlation(e, valid, u, lags)
        assert auto.band == pytest.approx(2.5758 / np.sqrt(n), rel=1e-4)
        assert auto.values[0] == pytest.approx(1.0)
        outside_auto += auto.outside
        outside_cross += np.count_nonzero(np.abs(cross.values[1:-1]) > cross.band)
        passed += bool(auto.passes)
    assert 0.006 < outside_auto / (trials * lags) < 0.014
    assert 0.006 < outside_cross / (trials * (2 * lags - 1)) < 0.014
    # the pass rule (binomial 99th percentile) rejects white data in <= 1 % of cases;
    # 97 % leaves room for the binomial spread of 400 trials (std 0.5 %)
    assert passed / trials > 0.97
    assert band_99(100) == pytest.approx(0.25758, rel=1e-4)


def test_correlated_residual_fails_and_constant_input_is_undefined():
    rng = np.random.default_rng(3)
    valid = np.ones(1000, dtype=bool)
    drift = np.cumsum(rng.standard_normal(1000))  # a random walk: strongly correlated
    assert autocorrelation(drift, valid, 25).passes is False
    assert cross_correlation(rng.standard_normal(1000), valid, np.ones(1000), 25).passes is None


def test_k_step_prediction_beats_simulation_on_a_drifted_model(diagonal):
    # Table 4.2 off by 25-40 % in damping and stiffness: the open-loop simulation drifts
    # away while a prediction 10 samples ahead of a state estimated from data stays close.
    drifted = TABLE.replace_values(
        b_cart=TABLE.values["b_cart"] * 1.4,
        b_bridge=TABLE.values["b_bridge"] * 0.7,
        k_l=TABLE.values["k_l"] * 0.75,
    )
    result = validate([drifted], [diagonal], ValidationOptions(horizon=10))
    for ch in result.recordings[0].runs[0].channels:
        assert ch.prediction_fit_percent >= ch.simulation_fit_percent, ch.name
        assert ch.prediction_fit_percent > 95.0, ch.name


def test_signals_and_rigs_are_checked_by_name():
    one_axis = load_parameter_file(ROOT / "models" / "one-axis-table2.3.yaml")
    h20 = load_parameter_file(ROOT / "models" / "hframe-20-table3.1.yaml")
    rec = simulate_recording(TABLE, _steps(-2.0, 2.0, n=60), seed=0)
    with pytest.raises(OptionError, match="takes inputs"):
        check_inputs([one_axis], [rec])
    check_inputs([h20], [rec])  # hframe-20 on hframe-8 data: same inputs and outputs
    rec = replace(rec, rig={**rec.rig, "serial_number": "rig-1"})
    other = replace(rec, rig={**rec.rig, "serial_number": "rig-2"})
    with pytest.raises(OptionError, match="different rigs"):
        check_inputs([TABLE], [rec, other])
    no_y = replace(rec, outputs=rec.outputs[:, :3], output_names=rec.output_names[:3])
    with pytest.raises(OptionError, match="does not measure y"):
        check_inputs([TABLE], [no_y])
    with pytest.raises(OptionError, match="horizon"):
        ValidationOptions(horizon=-1)


def test_leave_one_out_on_small_simulated_recordings():
    # Three 0.3 s steps from Table 4.2 with the rig's sensors; two parameters free from a
    # start 30 % / 20 % off, so every fold is a small fit (seconds).
    recs = [
        replace(simulate_recording(TABLE, _steps(*v, n=300), seed=i), path=Path(f"r{i}.mcap"))
        for i, v in enumerate([(-3, 3), (-3, -3), (4, -2)])
    ]
    start = TABLE.replace_values(k_l=TABLE.values["k_l"] * 1.3, b_cart=TABLE.values["b_cart"] * 0.8)
    table = leave_one_out(recs, start, FitOptions(free=("k_l", "b_cart"), verbose=0))
    assert [f.held_out for f in table.folds] == ["r0.mcap", "r1.mcap", "r2.mcap"]
    assert all(f.success for f in table.folds)
    for fold in table.folds:
        # the motors turn in every step: the held-out motor angles are predicted to 99 %
        assert fold.fit_percent["phi1"] > 99.0 and fold.fit_percent["phi2"] > 99.0
    spread = {s.name: s for s in table.spread}
    # noise-level data from the true model: every fold lands within 0.1 % of the truth
    assert spread["k_l"].mean == pytest.approx(TABLE.values["k_l"], rel=1e-3)
    assert spread["b_cart"].relative_std_percent < 0.1
    # delete-one jackknife: (n - 1) / sqrt(n) times the folds' sample std, n = 3 folds
    values = [f.parameters["k_l"] for f in table.folds]
    assert spread["k_l"].jackknife_std == pytest.approx(2 / 3**0.5 * np.std(values, ddof=1))
    assert "| r1.mcap | converged |" in table.markdown()
    with pytest.raises(FitError, match="at least two"):
        leave_one_out(recs[:1], start)


def test_the_report_says_when_parameters_move_more_than_their_intervals():
    from types import SimpleNamespace

    from hframe_id.fitting.report_tables import jackknife_sentence
    from hframe_id.validation.cross_validation import LeaveOneOutTable, Spread

    def spread(name, jackknife):
        return Spread(name, "N", 1.0, jackknife, 0.9, 1.1, 10.0, jackknife)

    table = LeaveOneOutTable(("x",), (), (spread("F_c", 0.5), spread("M", 0.01)))
    result = SimpleNamespace(estimates={n: SimpleNamespace(std_error=0.1) for n in ("F_c", "M")})
    sentence = " ".join(jackknife_sentence(result, table))
    assert "F_c (5x)" in sentence and "M (" not in sentence
    table = LeaveOneOutTable(("x",), (), (spread("M", 0.01),))
    assert jackknife_sentence(result, table) == []


def test_allowed_outside_is_the_binomial_quantile():
    """Exact integers: the 0.99 quantile of Binomial(n, 0.01) as scipy.stats computes it, for
    every lag count from 0 to 3000 and two far beyond any correlation plot (10^5, 10^6)."""
    from scipy import stats

    from hframe_id.validation.residuals import allowed_outside

    for n in [*range(3001), 10**5, 10**6]:
        assert allowed_outside(n) == int(stats.binom.ppf(0.99, n, 0.01)), n
