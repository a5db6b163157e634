"""The solver seam (``fitting.solvers``): solvers are registered by name, and built-in names
and objects that cannot solve are refused. Every solver on every transcription:
integration/test_cross_method.py."""

from __future__ import annotations

import pytest

from examples.scipy_solver import ScipyLeastSquares
from hframe_id.errors import OptionError
from hframe_id.fitting import FitOptions
from hframe_id.fitting.solvers import register_solver, solver_names


@pytest.fixture(scope="module")
def scipy_solver():
    register_solver("scipy-least-squares", ScipyLeastSquares())
    return "scipy-least-squares"


def test_a_registered_solver_is_an_option_and_an_unknown_one_is_refused(scipy_solver):
    assert scipy_solver in solver_names()
    assert FitOptions(solver=scipy_solver).solver == scipy_solver
    with pytest.raises(OptionError, match="solver must be one of gauss-newton, ipopt"):
        FitOptions(solver="newton-raphson")


def test_built_in_names_and_objects_without_solve_are_refused():
    with pytest.raises(OptionError, match="built in"):
        register_solver("ipopt", ScipyLeastSquares())
    with pytest.raises(OptionError, match="no solve"):
        register_solver("nothing", object())
