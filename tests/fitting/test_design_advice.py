"""Experiment-design advice (``fitting.design_advice``): which standard experiments, alone or
only all together, would identify a parameter the data do not.

The combination rules are checked on information matrices chosen by hand (the data's from a
stand-in Jacobian, the candidates' in place of their simulation); the candidates'
information itself on a real transcription. Whole fits with advice:
integration/test_identifiability_fit.py."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hframe_id.design.information import reduced_information
from hframe_id.errors import FitError
from hframe_id.fitting import design_advice
from hframe_id.fitting.designs import Design
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import GaussNewton
from hframe_id.simulation.open_loop import simulate

#: Relative standard error at which a parameter counts as identified (FitOptions' default
#: ``identifiability_threshold``).
THRESHOLD = 0.1


def _advise(monkeypatch, candidates, present=(), relative_std=(), relative_std_gn=(), scale=1.0):
    """The advice for parameter b of two free log-parameters (a, b) whose data information is
    diag(1e4, 1) (standard errors 0.01 and 1: a identified, b not), given candidate designs
    ``{name: information of b}`` (None: its simulation fails)."""
    jac = np.diag([100.0, 1.0])  # J^T J = diag(1e4, 1); no initial states estimated
    problem = SimpleNamespace(
        free=(0, 1),
        free_names=("a", "b"),
        parameter_set=lambda theta: np.exp(theta),
        experiments=[SimpleNamespace(name=f"{n}.mcap") for n in present],
        model=SimpleNamespace(variant="hframe-8"),
        sample_period_s=1e-3,
    )
    gn = SimpleNamespace(condensed_jacobian=lambda ev, nodes, free: (jac, None, None))
    state = SimpleNamespace(evaluation=None, nodes=None, theta=np.zeros(2))
    stats = SimpleNamespace(
        relative_std=np.array(relative_std),
        relative_std_gn=np.array(relative_std_gn),
        noise_scale=scale,
    )
    designs = [Design(name, "hframe-8", np.zeros((1, 2)), "") for name in candidates]

    def information(problem, ms, design, fitted):
        b = candidates[design.name]
        if b is None:
            raise FitError("too few valid samples")
        return np.diag([0.0, b])

    monkeypatch.setattr(design_advice, "standard_designs", lambda variant, period: designs)
    monkeypatch.setattr(design_advice, "_design_information", information)
    ms = SimpleNamespace(n_nuisance=0)
    return design_advice.identifying_designs(problem, ms, gn, state, stats, ("b",), THRESHOLD)["b"]


# Information about b: 1 from the data; a candidate adding 120 gives std 1/sqrt(121) = 0.091
# (identified), one adding 60 gives 1/sqrt(61) = 0.128 (not); two of 60 together 0.091.


def test_each_design_that_alone_identifies_the_parameter_is_named(monkeypatch):
    advice = _advise(monkeypatch, {"6V_ymotion": 120.0, "2V_ymotion": 60.0, "4V_ymotion": 200.0})
    assert advice == ("6V_ymotion", "4V_ymotion")


def test_designs_that_only_identify_it_together_are_named_together(monkeypatch):
    advice = _advise(monkeypatch, {"2V_ymotion": 60.0, "4V_ymotion": 60.0})
    assert advice == ("all of 2V_ymotion, 4V_ymotion",)


def test_no_advice_when_even_all_designs_together_do_not_identify_it(monkeypatch):
    assert _advise(monkeypatch, {"2V_ymotion": 30.0, "4V_ymotion": 30.0}) == ()


def test_designs_already_in_the_data_and_designs_that_cannot_be_simulated_are_left_out(
    monkeypatch,
):
    """The data have 6V_ymotion; 4V_ymotion cannot be simulated (FitError): of the three,
    only 2V_ymotion is a candidate, and alone it does not identify b."""
    candidates = {"6V_ymotion": 120.0, "4V_ymotion": None, "2V_ymotion": 60.0}
    assert _advise(monkeypatch, candidates, present=("6V_ymotion",)) == ()
    assert _advise(monkeypatch, candidates) == ("6V_ymotion",)


@pytest.mark.parametrize(
    ("relative_std", "relative_std_gn", "scale", "identified"),
    [
        ([0.2, 0.25, 0.3], [0.1, 0.1, 0.1], 1.0, False),  # robust / textbook: median 2.5
        ([0.1, 0.1, 0.2], [0.1, 0.1, 0.1], 1.0, True),  # median 1
        ([0.1, 0.3, 0.3, 0.0], [0.1, 0.1, 0.0, 0.0], 1.0, True),  # x / 0 left out: median 2
        ([], [], 2.5, False),  # no statistics: ratio 1, times the noise scale
    ],
)
def test_the_predicted_error_is_scaled_like_the_datas(
    monkeypatch, relative_std, relative_std_gn, scale, identified
):
    """The candidate brings b's textbook error to 1/sqrt(481) = 0.0456; scaled by 2.5 (the
    median ratio of robust to textbook errors, or the noise scale) it is 0.114 > 0.1. The
    ratios of a zero textbook error (inf, nan) are left out: the median of 1 and 3 is 2
    (0.091, identified); with them it would be inf."""
    advice = _advise(monkeypatch, {"6V_ymotion": 480.0}, (), relative_std, relative_std_gn, scale)
    assert advice == (("6V_ymotion",) if identified else ())


def test_a_design_repeating_the_datas_experiment_adds_about_the_datas_information(
    table_and_step,
):
    """The candidate's information (simulated noise-free through the rig's DAC at the fitted
    parameters, weighted by the data's noise levels) for the data's own inputs is the data's
    Gauss-Newton information at the same point. The point: k_b x 1.3, M_cart x 0.8 from the
    start (so the fitted parameters are not the initial ones), noise levels 9x and 2x the
    rig's (so the weights are not the rig's).

    Compared in units of the data's diagonal: the two are computed on different
    discretisations (the design's transcription has its own substeps, the data's here the
    stiffest window's in every window), which moves the entries by up to 4 %, and those of
    the stiff motor-2 inertia J_M2 by 17 % (measured); hence 0.1 and 0.3. A candidate at
    the initial instead of the fitted parameters is off by 1.15, one weighted by the rig's
    noise levels by 83 (measured): either fails the test."""
    table, recording = table_and_step
    std = {"phi1": 5e-5, "phi2": 5e-5, "x": 1e-5, "y": 1e-5}
    problem = build_problem([recording], table, FitOptions(channel_std=std))
    ms = MultipleShooting(problem).uniform()
    theta = np.zeros(len(problem.free))
    theta[problem.free_names.index("k_b")] = np.log(1.3)
    theta[problem.free_names.index("M_cart")] = np.log(0.8)
    p = problem.parameters(theta)
    substeps = ms.substep_plan(p, problem.smoothing)["stiff"]
    inputs = problem.experiments[0].inputs
    nodes = simulate(ms.model, p, inputs, 1e-3, n_substeps=substeps)[ms.window_start]
    ev = ms.evaluate(nodes, theta, problem.smoothing)
    jac, _, _ = GaussNewton(ms).condensed_jacobian(ev, nodes, np.ones(theta.size, dtype=bool))
    data = reduced_information(jac, ms.n_nuisance)
    design = Design("same", "hframe-8", recording.inputs, "the data's inputs")
    candidate = design_advice._design_information(problem, ms, design, problem.parameter_set(theta))
    scale = np.sqrt(np.outer(np.diag(data), np.diag(data)))
    difference = np.abs(candidate - data) / scale
    j = problem.free_names.index("J_M2")
    assert difference[j, j] <= 0.3
    difference[j, :] = difference[:, j] = 0.0
    assert np.max(difference) <= 0.1
