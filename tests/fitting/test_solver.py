"""The condensed Gauss-Newton solver's merit function (``fitting.solver``)."""

from hframe_id.fitting.solver import MERIT_RHO, _penalty_parameter


def test_penalty_parameter_makes_every_full_step_predict_a_decrease():
    for change, l1 in ((10.0, 1.0), (1e9, 3.0), (-5.0, 2.0), (0.5, 4.0)):
        mu = _penalty_parameter(1.0, change, l1)
        assert mu >= 1.0
        assert mu * l1 - change >= MERIT_RHO * mu * l1 - 1e-9 * abs(change)
