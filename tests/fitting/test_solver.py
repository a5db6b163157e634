"""The condensed Gauss-Newton solver's merit function and its overflow verdict
(``fitting.solver``)."""

import dataclasses
import warnings

import numpy as np
import pytest

from hframe_id.fitting.gauss_newton_settings import GaussNewtonSettings
from hframe_id.fitting.solver import GaussNewton, SolverState, _penalty_parameter, _Walk


@pytest.mark.parametrize("rho", [GaussNewtonSettings.merit_rho, 0.5])
def test_penalty_parameter_makes_every_full_step_predict_a_decrease(rho):
    for change, l1 in ((10.0, 1.0), (1e9, 3.0), (-5.0, 2.0), (0.5, 4.0)):
        mu = _penalty_parameter(1.0, change, l1, rho)
        assert mu >= 1.0
        assert mu * l1 - change >= rho * mu * l1 - 1e-9 * abs(change)


def test_overflowing_sensitivities_stop_the_step_without_numpy_warnings(shooting_setup):
    """Sensitivities too large to square (a parameter run far off) make the linearisation
    non-finite: the step says so (``overflowed``, which ends the stage with that reason)
    and nothing is printed (the fit's command line showed every numpy RuntimeWarning)."""
    problem, ms, nodes, _ = shooting_setup
    theta = np.zeros(len(problem.free))
    gn = GaussNewton(ms)
    gn.set_smoothing(problem.smoothing)
    ev = ms.evaluate(nodes, theta, problem.smoothing)
    huge = dataclasses.replace(ev, jac_theta=ev.jac_theta * 1e300)
    state = SolverState(nodes, theta, np.ones(len(theta), dtype=bool), evaluation=huge)
    walk = _Walk(ms, gn.links, None, 0.5, False)
    walk.best = (walk.merit(huge, nodes), nodes, theta, huge)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        trial = gn._trial(walk, state, problem.smoothing, 1)
    assert trial.overflowed and not trial.accepted
