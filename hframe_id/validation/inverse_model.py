"""The inverse-model force error (IDIM), as Script_IDIM_LS.m computes it for EMPS.

Robotics judges a rigid-body model by how well it predicts the actuator force from the measured
motion (Janot et al. 2019, section 3; IDIM-LS 4.08 % on the estimation set): the measured
position is filtered and differentiated twice (``benchmark_filters.filtered_motion``), the model
predicts the force the inputs must produce, F_hat = M (qddot_f - f(q_f, qdot_f, 0))
(``input_forces``), and after the 49-sample border both F_hat and the inputs' force (EMPS:
gtau vir) are decimated by ``decimation_factor`` (10 at 1 kHz) with MATLAB's ``decimate``:

    error [%] = 100 ||F - F_hat|| / ||F||

The script decimates the regressor's columns and multiplies by the parameters; for a model
linear in its parameters (EMPS) that is the same as decimating F_hat, which any model has.
Every coordinate must be measured at every sample.
"""

from __future__ import annotations

from dataclasses import dataclass

from hframe_id.fitting.dataset import Dataset
from hframe_id.models import build_model
from hframe_id.parameters import ParameterSet
from hframe_id.simulation.friction import FrictionOptions
from hframe_id.validation.benchmark_filters import (
    BORDER_SAMPLES,
    ScoreUnavailable,
    decimation_factor,
    matlab_decimate,
    relative_error_percent,
)
from hframe_id.validation.input_forces import input_forces, measured_motion


@dataclass(frozen=True)
class InverseModelScore:
    """The inverse-model force error of one parameter set on one recording.

    Attributes
    ----------
    force_error_percent : 100 ||F - F_hat|| / ||F|| [%], None where ``unavailable``.
    decimation : the decimation factor r.
    samples : decimated samples compared.
    friction : the Coulomb law of the prediction (``"sign"``: the script's sign(dq_f)).
    unavailable : why there is no error (a coordinate not measured, too short a record).
    """

    force_error_percent: float | None
    decimation: int
    samples: int
    friction: str
    unavailable: str | None = None


def inverse_model_score(
    params: ParameterSet, data: Dataset, friction: FrictionOptions
) -> InverseModelScore:
    """The IDIM force error of ``params`` on a recording's channels (module docstring)."""
    model = build_model(params.variant)
    p = model.parameter_vector(params.values)
    factor = decimation_factor(data.sample_period_s)
    try:
        x_f, ddq_f = measured_motion(model, data)
    except ScoreUnavailable as err:
        return InverseModelScore(None, factor, 0, friction.model, str(err))
    force, predicted = input_forces(model, p, x_f, data.inputs, ddq_f, friction)
    force = matlab_decimate(force[BORDER_SAMPLES:], factor)
    predicted = matlab_decimate(predicted[BORDER_SAMPLES:], factor)
    error = relative_error_percent(force, predicted, border=0)
    return InverseModelScore(error, factor, force.shape[0], friction.model)
