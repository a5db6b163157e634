"""Points the fit knows (``fitting.known_points``): the reference files, and the simulation
criterion they are judged by."""

import dataclasses

import numpy as np
import pytest

from hframe_id.fitting.known_points import (
    Criterion,
    held_criterion,
    reference_sets,
    simulation_criterion,
    unforced,
)
from hframe_id.models import build_model
from hframe_id.validation.replay import channels


def test_the_models_reference_files_are_known_points():
    labels = [label for label, _ in reference_sets("hframe-8")]
    assert labels == ["hframe-8-table4.1.yaml", "hframe-8-table4.2.yaml"]


def _squares_and_counts(params, recordings):
    """Per recording, per channel: the free run's sum of squared residuals [SI^2] and valid
    samples."""
    from hframe_id.validation.replay import simulate_channels

    squares, counts = [], []
    for rec in recordings:
        data, simulated = simulate_channels(params, rec)
        squares.append({}), counts.append({})
        for j, name in enumerate(data.names):
            r = (data.measured[:, j] - simulated[:, j])[data.valid[:, j]]
            squares[-1][name], counts[-1][name] = float(r @ r), r.size
    return squares, counts


def test_the_concentrated_criterion_gives_each_point_its_own_noise_levels(table, truth, steps):
    """sum_ej N_ej / 2 ln(SSR_ej / N_ej): the chi^2 / 2 criterion at the noise levels, one
    per recording and channel, that are each point's own maximum-likelihood ones, less a
    constant (floors far below them)."""
    squares, counts = _squares_and_counts(table, steps)
    floors = dict.fromkeys(squares[0], 1e-12)
    concentrated = simulation_criterion(table, steps, floors, concentrated=True)
    own_levels = [
        {n: np.sqrt(sq[n] / c[n]) for n in sq} for sq, c in zip(squares, counts, strict=True)
    ]
    at_own_levels = simulation_criterion(table, steps, own_levels)
    constant = sum(
        0.5 * c[n] * (np.log(level[n] ** 2) - 1.0)
        for level, c in zip(own_levels, counts, strict=True)
        for n in c
    )
    assert concentrated == pytest.approx(at_own_levels + constant, rel=1e-12)
    # One level per channel pooled over the recordings is a constraint on the levels: the
    # concentrated criterion (their best) is lower than chi^2 / 2 at the pooled ones + const.
    pooled = {n: np.sqrt(sum(sq[n] for sq in squares) / sum(c[n] for c in counts)) for n in floors}
    constant_pooled = sum(
        0.5 * sum(c[n] for c in counts) * (np.log(pooled[n] ** 2) - 1.0) for n in floors
    )
    assert concentrated < simulation_criterion(table, steps, pooled) + constant_pooled
    # The truth simulates these records better on every channel: lower either way.
    assert simulation_criterion(truth, steps, floors, concentrated=True) < concentrated


def test_the_concentrated_criterion_floors_the_levels_at_the_sensors(truth, steps):
    """A channel fitted below its sensor's noise is judged at the sensor's level: N / 2
    ln(std^2) + SSR / (2 std^2) - N / 2, not N / 2 ln(SSR / N), which goes to minus
    infinity as SSR does whatever the other channels do."""
    import math

    squares, counts = _squares_and_counts(truth, steps)
    # Floors above every recording's own level: all floored.
    floors = {
        n: 10 * max(math.sqrt(sq[n] / c[n]) for sq, c in zip(squares, counts, strict=True))
        for n in squares[0]
    }
    expected = sum(
        0.5 * c[n] * math.log(floors[n] ** 2) + 0.5 * sq[n] / floors[n] ** 2 - 0.5 * c[n]
        for sq, c in zip(squares, counts, strict=True)
        for n in sq
    )
    floored = simulation_criterion(truth, steps, floors, concentrated=True)
    assert floored == pytest.approx(expected, rel=1e-12)
    unfloored = simulation_criterion(truth, steps, dict.fromkeys(floors, 1e-12), concentrated=True)
    assert floored > unfloored


def test_the_held_criterion_is_each_channel_held_at_its_mean(truth, steps):
    """The prediction that nothing moves: each record's channels at their means, judged as
    the simulation criterion judges (here chi^2 / 2 under unit levels: SSR / 2 about each
    record's mean), and worse than the plant's own simulation."""

    model = build_model("hframe-8")
    expected = 0.0
    for rec in steps:
        data = channels(model, rec)
        for j in range(len(data.names)):
            y = data.measured[data.valid[:, j], j]
            expected += 0.5 * float(np.sum((y - y.mean()) ** 2))
    units = dict.fromkeys(channels(model, steps[0]).names, 1.0)
    assert held_criterion(steps, units, None, False, "hframe-8") == pytest.approx(
        expected, rel=1e-12
    )
    floors = dict.fromkeys(units, 1e-12)
    held = held_criterion(steps, floors, None, True, "hframe-8")
    assert simulation_criterion(truth, steps, floors, concentrated=True) < held


def test_a_fits_free_runs_are_simulated_once(monkeypatch, table, steps):
    """``Simulations``: a parameter set from the same initial states is simulated once,
    whatever criterion judges it; another set, or other states, are simulated anew."""
    from hframe_id.fitting import known_points

    runs = []
    real = known_points._simulated

    def counted(params, recordings, initial_states):
        runs.append(params)
        return real(params, recordings, initial_states)

    monkeypatch.setattr(known_points, "_simulated", counted)
    std = {"phi1": 5.65e-6, "phi2": 5.65e-6, "x": 5e-6, "y": 5e-6}
    simulations = known_points.Simulations()
    plain = simulation_criterion(table, steps, std, simulations=simulations)
    concentrated = simulation_criterion(table, steps, std, None, None, True, simulations)
    assert len(runs) == 1
    # The same numbers as without the memo.
    assert plain == simulation_criterion(table, steps, std)
    assert concentrated == simulation_criterion(table, steps, std, concentrated=True)
    assert len(runs) == 3
    other = table.replace_values(k_l=1.1 * table.values["k_l"])
    simulation_criterion(other, steps, std, simulations=simulations)
    x0 = [np.zeros(8)] * len(steps)
    simulation_criterion(table, steps, std, None, x0, simulations=simulations)
    assert len(runs) == 5


def test_against_unforced_judges_the_model_its_inputs_held_and_the_held_mean_under_the_fits_levels(
    truth, steps
):
    """All three predictions are weighed by the levels the fit reports, per recording (here
    the second recording's at twice the first's), not each by its own: the plant explains
    its two x-steps, better than with its inputs held at their start (at rest: it stays
    there) and than the held means; with the voltages zeroed (motion kept) the model and
    the model unforced are one simulation, and the held mean, the best constant, beats it."""

    names = channels(build_model("hframe-8"), steps[0]).names
    levels = ({name: 1e-5 for name in names}, {name: 2e-5 for name in names})
    criterion = Criterion(tuple(steps), levels[0], {}, True, fit_levels=levels)
    model, still, held = criterion.against_unforced(truth, None)
    assert model == pytest.approx(simulation_criterion(truth, steps, levels), rel=1e-12)
    assert still == pytest.approx(simulation_criterion(truth, unforced(steps), levels), rel=1e-12)
    assert held == pytest.approx(held_criterion(steps, levels, None, False, "hframe-8"), rel=1e-12)
    assert model < held - 1.92 and model < still - 1.92
    zeroed = tuple(dataclasses.replace(rec, inputs=np.zeros_like(rec.inputs)) for rec in steps)
    criterion = Criterion(zeroed, levels[0], {}, True, fit_levels=levels)
    model, still, held = criterion.against_unforced(truth, None)
    assert model == pytest.approx(still, rel=1e-12)
    assert held < model


def test_unforced_holds_every_input_at_its_first_value_and_keeps_the_rest(steps):
    held = unforced(steps)
    for rec, still in zip(steps, held, strict=True):
        assert np.array_equal(still.inputs, np.broadcast_to(rec.inputs[:1], rec.inputs.shape))
        assert np.array_equal(still.outputs, rec.outputs) and still.time_s is rec.time_s
    assert np.ptp(steps[0].inputs) > 0  # the steps do move their inputs


def test_against_unforced_without_the_fits_levels_uses_the_criterions_std(truth, steps):

    std = {name: 1e-5 for name in channels(build_model("hframe-8"), steps[0]).names}
    model, still, held = Criterion(tuple(steps), std, {}, False).against_unforced(truth, None)
    assert model == pytest.approx(simulation_criterion(truth, steps, std), rel=1e-12)
    assert still == pytest.approx(simulation_criterion(truth, unforced(steps), std), rel=1e-12)
    assert held == pytest.approx(held_criterion(steps, std, None, False, "hframe-8"), rel=1e-12)
