"""Shared fixtures of the fitting tests.

Layout: the unit tests of ``hframe_id/fitting/<module>.py`` are in ``test_<module>.py`` here
(fast: no whole fit, except where a module acts only through one, e.g. held_uncertainty);
whole fits and whole commands are in ``integration/``, named by what they check, and marked
``integration`` by their path (``pytest -m "not integration"`` runs the unit tests alone).
A module fixture that runs a fit stays in one file: each file runs on one xdist worker
(``--dist loadfile``), so splitting it would run the fit twice."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from hframe_id.fitting import FitOptions
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording
from hframe_id.simulation.open_loop import simulate

MODELS = Path(__file__).resolve().parents[2] / "models"


@pytest.fixture(scope="module")
def table():
    """Table 4.2 (hframe-8), the default start."""
    return load_parameter_file(MODELS / "hframe-8-table4.2.yaml")


def _x_step(params, seed: int, volts: float = 4.0):
    u = np.zeros((400, 2))
    u[50:350] = (-volts, volts)
    return simulate_recording(params, u, seed=seed)


@pytest.fixture(scope="session")
def x_step():
    """``x_step(params, seed, volts=4.0)``: a 0.4 s x-motion step of ``params`` from rest (50
    samples of pre-roll) recorded by the sim rig's sensors."""
    return _x_step


@pytest.fixture(scope="module")
def truth(table):
    """Table 4.2 with k_l, M_cart and F_c_cart moved (-5 %, +10 %, -25 %): a plant the start
    is near but not at."""
    return table.replace_values(k_l=12500.0, M_cart=1.15, F_c_cart=0.3)


@pytest.fixture(scope="module")
def steps(truth, x_step):
    """Two 0.4 s x-motion steps (+4 V and -4 V) of ``truth`` from rest."""
    return [x_step(truth, seed=3), x_step(truth, seed=4, volts=-4.0)]


@pytest.fixture(scope="session")
def in_motion():
    """``in_motion(recording, first)``: the recording from sample ``first`` on, a record that
    starts in motion (its time from 0)."""

    def cut(recording, first: int = 150):
        return dataclasses.replace(
            recording,
            time_s=recording.time_s[first:] - recording.time_s[first],
            inputs=recording.inputs[first:],
            outputs=recording.outputs[first:],
            valid=recording.valid[first:],
        )

    return cut


@pytest.fixture(scope="module")
def small_result(table):
    """``small_result(**changes)``: a ``FitResult`` made by hand (no fit) on Table 4.2: k_l
    free and identified (12500 N/m, relative std 1 %), M_cart fixed; ``changes`` replace
    its fields."""
    from hframe_id.fitting import FitOptions
    from hframe_id.fitting.result import FitResult, ParameterEstimate

    def make(**changes):
        k_l = ParameterEstimate(
            "k_l", "N/m", 13167.0, 12500.0, 125.0, (12255.0, 12747.0), True, True, 0.01
        )
        m_cart = ParameterEstimate(
            "M_cart", "kg", 1.0412, 1.0412, 0.0, (1.0412, 1.0412), False, False
        )
        result = FitResult(
            success=True,
            message="converged",
            parameters=table.replace_values(k_l=12500.0),
            estimates={"k_l": k_l, "M_cart": m_cart},
            cost=1234.5,
            iterations=7,
            wall_time_s=0.5,
            correlation=np.eye(1),
            free_names=("k_l",),
            initial=table,
            options=FitOptions(free=("k_l",)),
        )
        return dataclasses.replace(result, **changes)

    return make


@pytest.fixture(scope="module")
def recording(table):
    """A 0.2 s x-motion step (-4 V, 4 V) of Table 4.2 from rest (50 samples of pre-roll)."""
    u = np.zeros((300, 2))
    u[50:250] = (-4.0, 4.0)
    return simulate_recording(table, u, seed=1)


@pytest.fixture(scope="module")
def table_and_step(table):
    """(Table 4.2, a 0.2 s step of it with unequal voltages (-4 V, 2 V), from rest)."""
    u = np.zeros((300, 2))
    u[50:250] = (-4.0, 2.0)
    return table, simulate_recording(table, u, seed=4)


@pytest.fixture(scope="module")
def shooting_setup(table):
    """(problem, uniform transcription, nodes on the simulated trajectory, the states) of a
    0.25 s step (-4 V, 2 V) of Table 4.2, simulated with the stiffest window's substeps."""
    u = np.zeros((400, 2))
    u[50:300] = (-4.0, 2.0)
    rec = simulate_recording(table, u, seed=4)
    problem = build_problem([rec], table, FitOptions())
    ms = MultipleShooting(problem).uniform()
    p = problem.p_initial
    n_sub = ms.substep_plan(p, problem.smoothing)["stiff"]
    states = simulate(ms.model, p, problem.experiments[0].inputs, 1e-3, n_substeps=n_sub)
    nodes = states[ms.window_start]
    return problem, ms, nodes, states


@pytest.fixture(scope="module")
def exact_shooting(shooting_setup):
    """(problem, uniform transcription, nodes) of ``shooting_setup``'s step with outputs that
    are the transcription's own simulation of Table 4.2 (no noise, no quantisation) and
    k_b, M_cart, b_bridge free: the optimum is the start, theta = 0, with cost and
    continuity defects 0, a reference the solvers must reach from nearby."""
    problem, ms, nodes, states = shooting_setup
    experiment = problem.experiments[0]
    exact = dataclasses.replace(experiment.recording, outputs=states[:-1] @ ms.c.T)
    options = FitOptions(free=("k_b", "M_cart", "b_bridge"))
    exact_problem = build_problem([exact], problem.initial, options)
    exact_ms = MultipleShooting(exact_problem).uniform()
    return exact_problem, exact_ms, states[exact_ms.window_start]
