"""What a fit produced (``fitting.result``): frozen results, the statements they make."""

from pathlib import Path

from hframe_id.parameters import load_parameter_file

MODELS = Path(__file__).resolve().parents[2] / "models"


def test_held_parameters_and_their_prior_are_stated():
    """A fit with held table values says which, at what value and with what prior."""
    from hframe_id.fitting.consider import Consider
    from hframe_id.fitting.result import FitDiagnostics, FitResult

    def held(prior: dict) -> FitResult:
        result = FitResult.__new__(FitResult)
        object.__setattr__(result, "diagnostics", FitDiagnostics(consider=Consider(prior)))
        object.__setattr__(
            result, "parameters", load_parameter_file(MODELS / "one-axis-table2.3.yaml")
        )
        return result

    statement = held({"J_2": 0.2}).held_statement()
    assert "J_2 = 6.3e-05 (+/-20 %)" in statement and "consider covariance" in statement
    assert held({}).held_statement() is None
