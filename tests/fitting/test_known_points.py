"""Points the fit knows (``fitting.known_points``): the reference files, and the simulation
criterion they are judged by."""

import numpy as np
import pytest

from hframe_id.fitting.known_points import reference_sets, simulation_criterion


def test_the_models_reference_files_are_known_points():
    labels = [label for label, _ in reference_sets("hframe-8")]
    assert labels == ["hframe-8-table4.1.yaml", "hframe-8-table4.2.yaml"]


def _squares_and_counts(params, recordings):
    """Per channel: the free run's sum of squared residuals [SI^2] and valid samples."""
    from hframe_id.validation.replay import simulate_channels

    squares, counts = {}, {}
    for rec in recordings:
        data, simulated = simulate_channels(params, rec)
        for j, name in enumerate(data.names):
            r = (data.measured[:, j] - simulated[:, j])[data.valid[:, j]]
            squares[name] = squares.get(name, 0.0) + float(r @ r)
            counts[name] = counts.get(name, 0) + r.size
    return squares, counts


def test_the_concentrated_criterion_gives_each_point_its_own_noise_levels(table, truth, steps):
    """sum_j N_j / 2 ln(SSR_j / N_j): the chi^2 / 2 criterion at the noise levels that are
    each point's own maximum-likelihood ones, less a constant (floors far below them)."""
    squares, counts = _squares_and_counts(table, steps)
    floors = dict.fromkeys(squares, 1e-12)
    concentrated = simulation_criterion(table, steps, floors, concentrated=True)
    own_levels = {n: np.sqrt(squares[n] / counts[n]) for n in squares}
    at_own_levels = simulation_criterion(table, steps, own_levels)
    constant = sum(0.5 * counts[n] * (np.log(own_levels[n] ** 2) - 1.0) for n in squares)
    assert concentrated == pytest.approx(at_own_levels + constant, rel=1e-12)
    # The truth simulates these records better on every channel: lower either way.
    assert simulation_criterion(truth, steps, floors, concentrated=True) < concentrated


def test_the_concentrated_criterion_floors_the_levels_at_the_sensors(truth, steps):
    """A channel fitted below its sensor's noise is judged at the sensor's level: N / 2
    ln(std^2) + SSR / (2 std^2) - N / 2, not N / 2 ln(SSR / N), which goes to minus
    infinity as SSR does whatever the other channels do."""
    import math

    squares, counts = _squares_and_counts(truth, steps)
    floors = {n: 10 * math.sqrt(squares[n] / counts[n]) for n in squares}  # all floored
    expected = sum(
        0.5 * counts[n] * math.log(floors[n] ** 2)
        + 0.5 * squares[n] / floors[n] ** 2
        - 0.5 * counts[n]
        for n in squares
    )
    floored = simulation_criterion(truth, steps, floors, concentrated=True)
    assert floored == pytest.approx(expected, rel=1e-12)
    unfloored = simulation_criterion(truth, steps, dict.fromkeys(floors, 1e-12), concentrated=True)
    assert floored > unfloored


def test_the_held_criterion_is_each_channel_held_at_its_mean(truth, steps):
    """The prediction that nothing moves: each record's channels at their means, judged as
    the simulation criterion judges (here chi^2 / 2 under unit levels: SSR / 2 about each
    record's mean), and worse than the plant's own simulation."""
    from hframe_id.fitting.known_points import held_criterion
    from hframe_id.models import build_model
    from hframe_id.validation.replay import channels

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
