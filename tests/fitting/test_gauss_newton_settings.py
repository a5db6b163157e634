"""The Gauss-Newton iteration's tuning as an option (``fitting.gauss_newton_settings``):
checked on construction, recorded where it differs from the defaults, and read by every
iteration a fit builds."""

import numpy as np
import pytest

from hframe_id.errors import OptionError
from hframe_id.fitting.fit_run import FitRun
from hframe_id.fitting.gauss_newton_settings import GaussNewtonSettings
from hframe_id.fitting.option_checks import changed_fields
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.solver import GaussNewton, SolverState


def test_defaults_are_recorded_as_default_and_a_change_by_name():
    assert changed_fields(GaussNewtonSettings()) == {}
    assert FitOptions().for_model("hframe-8").describe()["gauss_newton"] == "default"
    tuned = FitOptions(gauss_newton=GaussNewtonSettings(merit_rho=0.2, watchdog_patience=6))
    assert tuned.for_model("hframe-8").describe()["gauss_newton"] == {
        "merit_rho": 0.2,
        "watchdog_patience": 6,
    }
    assert tuned.solver_options.gauss_newton is tuned.gauss_newton


@pytest.mark.parametrize(
    ("given", "message"),
    [
        ({"merit_rho": 1.0}, "gauss_newton.merit_rho must be < 1, got 1.0"),
        ({"give_up_decrease": 0}, "gauss_newton.give_up_decrease must be > 0, got 0"),
        ({"watchdog_patience": 2.5}, "gauss_newton.watchdog_patience must be a whole number"),
        ({"max_radius": True}, "gauss_newton.max_radius must be a number, got True"),
        (
            {"sloppy_std": float("nan")},
            "gauss_newton.sloppy_std must be a finite number > 0, got nan",
        ),
        (
            {"min_radius": 5.0},
            "gauss_newton.min_radius must not exceed gauss_newton.max_radius, got 5.0 > 4.0",
        ),
        (
            {"node_damping": 1e9},
            "gauss_newton.node_damping must not exceed gauss_newton.max_node_damping",
        ),
    ],
)
def test_a_bad_setting_is_refused_naming_it_and_its_value(given, message):
    with pytest.raises(OptionError, match="^" + message.replace(".", r"\.")):
        GaussNewtonSettings(**given)


def test_fit_options_refuse_settings_of_another_type():
    with pytest.raises(OptionError, match="gauss_newton must be GaussNewtonSettings, got dict"):
        FitOptions(gauss_newton={"merit_rho": 0.2})


def test_a_fit_run_builds_its_iterations_with_the_options_settings(shooting_setup):
    _, ms, _, _ = shooting_setup
    tuned = GaussNewtonSettings(cost_window=3)
    run = FitRun(None, FitOptions(gauss_newton=tuned), ms, None, None, None, None, 0.0)
    gn = run.solver(ms, freeze_sloppy=True)
    assert gn.settings is tuned and gn.freeze_sloppy and gn.ms is ms


def test_the_iteration_reads_its_settings(exact_shooting):
    """From 2 % off the optimum a stage moves the parameters; with the smallest trust region
    above the stage's first radius (0.5) it cannot try a step, and stops at once where it
    started: the setting is what the iteration reads, not a module constant."""
    problem, ms, nodes = exact_shooting
    start = np.array([0.02, -0.02, 0.02])
    ends = []
    held_back = GaussNewtonSettings(min_radius=1.0, watchdog_min_radius=1.0)
    for settings in (GaussNewtonSettings(), held_back):
        state = SolverState(nodes.copy(), start.copy(), np.ones(3, dtype=bool))
        report = GaussNewton(ms, settings=settings).run(
            state, "all windows", problem.smoothing, 20, 1e-8, 1e-2, radius=0.5
        )
        ends.append((report.iterations, state.theta))
    (moved_iterations, moved), (held_iterations, held) = ends
    assert np.max(np.abs(moved)) < 1e-3 < np.max(np.abs(moved - start))
    assert held_iterations == 1 and np.array_equal(held, start)
