"""The stages' tuning as an option (``fitting.strategy_settings``): checked on construction,
recorded where it differs from the defaults, and read by the stages."""

import numpy as np
import pytest

from hframe_id.errors import OptionError
from hframe_id.fitting import FitOptions, StrategySettings
from hframe_id.fitting.option_checks import changed_fields
from hframe_id.fitting.solver import GaussNewton
from hframe_id.fitting.stages import estimate_states


def test_defaults_are_recorded_as_default_and_a_change_by_name():
    assert changed_fields(StrategySettings()) == {}
    assert FitOptions().for_model("hframe-8").describe()["strategy"] == "default"
    tuned = FitOptions(strategy=StrategySettings(max_noise_rounds=20, restart_factors=[1.5]))
    recorded = tuned.for_model("hframe-8").describe()["strategy"]
    assert recorded == {"max_noise_rounds": 20, "restart_factors": (1.5,)}


@pytest.mark.parametrize(
    ("given", "message"),
    [
        ({"max_noise_rounds": 0}, "strategy.max_noise_rounds must be > 0, got 0"),
        ({"box_widenings": -1}, "strategy.box_widenings must be >= 0, got -1"),
        ({"box_widenings": 1.0}, "strategy.box_widenings must be a whole number, got 1.0"),
        ({"noise_rtol": float("inf")}, "strategy.noise_rtol must be a finite number >= 0, got inf"),
        ({"mismatch_rms": "3"}, "strategy.mismatch_rms must be a number, got '3'"),
        ({"restart_factors": (1.2, 0.8)}, "strategy.restart_factors must be factors > 1"),
        ({"restart_factors": ()}, "strategy.restart_factors must be a sequence of factors > 1"),
    ],
)
def test_a_bad_setting_is_refused_naming_it_and_its_value(given, message):
    with pytest.raises(OptionError, match="^" + message.replace(".", r"\.")):
        StrategySettings(**given)


def test_zero_is_a_setting_where_it_means_something():
    """No widening, no restart, and a noise tolerance every change exceeds (every round runs)."""
    settings = StrategySettings(box_widenings=0, restart_limit=0, noise_rtol=0.0)
    assert changed_fields(settings) == {"box_widenings": 0, "restart_limit": 0, "noise_rtol": 0.0}


def test_fit_options_refuse_settings_of_another_type():
    with pytest.raises(OptionError, match="strategy must be StrategySettings, got dict"):
        FitOptions(strategy={"max_noise_rounds": 20})


def test_the_state_estimation_pre_pass_reads_its_iterations(exact_shooting):
    """The pre-pass runs at most ``prepass_iterations``: one iteration leaves the nodes
    further from the data's trajectory than the default's 30."""
    problem, ms, true_nodes = exact_shooting
    nodes, velocity = ms.initial_nodes(problem.p_initial)
    errors = []
    for settings in (StrategySettings(), StrategySettings(prepass_iterations=1)):
        stages = []
        estimated, _ = estimate_states(
            GaussNewton(ms), nodes, velocity, np.zeros(3), np.ones(3, dtype=bool), stages, settings
        )
        assert stages[-1].iterations <= settings.prepass_iterations
        errors.append(np.max(np.abs(estimated - true_nodes)))
    assert stages[-1].iterations == 1
    assert errors[0] < errors[1]
