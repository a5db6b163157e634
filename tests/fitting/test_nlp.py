"""CasADi's NLP solvers' settings (``fitting.nlp.NlpSettings``): one-line errors."""

import pytest

from hframe_id.errors import OptionError
from hframe_id.fitting.nlp import NlpSettings


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("solver", "snopt", "solver must be one of ipopt, sqpmethod, got 'snopt'"),
        ("qp_solver", "gurobi", "qp_solver must be one of qpoases, osqp, qrqp, got 'gurobi'"),
        ("tolerance", 0.0, "tolerance must be a number in (0, 1), got 0.0"),
        ("max_iter", 0, "max_iter must be a whole number in [1, 100000], got 0"),
        ("print_level", 1.5, "print_level must be a whole number in [0, 12], got 1.5"),
    ],
)
def test_bad_settings_give_one_line_errors(field, value, message):
    with pytest.raises(OptionError) as error:
        NlpSettings(**{field: value})
    assert str(error.value) == message
    assert "\n" not in str(error.value)
