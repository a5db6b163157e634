"""The closed-loop relative errors of the EMPS benchmark, for any model and declared controller.

Janot et al. (2019, sections 3.4-3.5) judge a model the way the rig ran: in closed loop with its
controller, from its reference (and force pulses). Here the model runs with a declared
controller (``hframe_id.control.loop``) from rest at the recording's first measured positions,
with the recording's references and disturbances, and sample k of the run is compared with
sample k of the recording, as Simulation_EMPS.m does:

- position, velocity, acceleration: each measured coordinate filtered and differentiated as
  the benchmark does (``benchmark_filters.filtered_motion``) against the simulated coordinate,
  its rate and its acceleration at the sample instants;
- force: the force the inputs produce (``input_forces``; EMPS: gtau vir), from the recorded
  inputs against the simulated ones;

each as 100 ||y - y_s|| / ||y|| without the first 49 samples, several channels counted together
(their samples stacked: one number per quantity, in SI units).
"""

from __future__ import annotations

from dataclasses import dataclass

from hframe_id.control.declaration import ControllerDeclaration
from hframe_id.control.loop import LoopResult, simulate_loop
from hframe_id.models import build_model
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording
from hframe_id.simulation.friction import FrictionOptions
from hframe_id.validation.benchmark_filters import (
    BORDER_SAMPLES,
    ScoreUnavailable,
    filtered_motion,
    relative_error_percent,
)
from hframe_id.validation.input_forces import input_forces, measured_motion
from hframe_id.validation.replay import channels, rest_state

#: The four quantities, in the order the benchmark reports them.
QUANTITIES = ("position", "velocity", "acceleration", "force")


@dataclass(frozen=True)
class ClosedLoopScore:
    """One parameter set in closed loop on one recording.

    Attributes
    ----------
    controller : the declared controller.
    run : the simulated closed loop (sample period, friction law, disturbances, stability).
    channels : the measured coordinates scored (position, velocity, acceleration).
    samples : samples compared (the run's, at most the recording's, minus the border).
    relative_error_percent : by quantity (``QUANTITIES``) [%]; None for an unstable run, a
        quantity None where it cannot be computed (``unavailable``).
    unavailable : why a quantity is None, by quantity.
    """

    controller: ControllerDeclaration
    run: LoopResult
    channels: tuple[str, ...]
    samples: int
    relative_error_percent: dict[str, float | None] | None
    unavailable: dict[str, str]


def closed_loop_score(
    params: ParameterSet,
    recording: Recording,
    controller: ControllerDeclaration,
    friction: FrictionOptions,
) -> ClosedLoopScore:
    """Run ``params``'s model in closed loop with ``controller`` on ``recording``'s references
    and score it (module docstring). Raises ``ControllerError`` if the controller does not fit
    the model or the recording."""
    model = build_model(params.variant)
    p = model.parameter_vector(params.values)
    data = channels(model, recording)
    run = simulate_loop(model, p, controller, recording, rest_state(model, p, data), friction)
    coordinates = [c.name for c in model.coordinates]
    scored = [j for j, n in enumerate(data.names) if n in coordinates and data.valid[:, j].all()]
    names = tuple(data.names[j] for j in scored)
    n = min(run.time_s.size, recording.n_samples)
    if not run.stable:
        return ClosedLoopScore(controller, run, names, 0, None, {})
    errors: dict[str, float | None] = dict.fromkeys(QUANTITIES)
    unavailable: dict[str, str] = {}
    try:
        if not scored:
            raise ScoreUnavailable("no coordinate is measured at every sample")
        measured = filtered_motion(data.measured[:, scored], data.sample_period_s)
        index = [coordinates.index(name) for name in names]
        n_q = model.n_states // 2
        simulated = (
            run.states[:, index],
            run.states[:, [n_q + i for i in index]],
            run.accelerations[:, index],
        )
        for quantity, y, y_s in zip(QUANTITIES, measured, simulated, strict=False):
            errors[quantity] = relative_error_percent(y[:n], y_s[:n])
    except ScoreUnavailable as err:
        unavailable.update(dict.fromkeys(QUANTITIES[:3], str(err)))
    try:
        x_f, ddq_f = measured_motion(model, data)
        force, _ = input_forces(model, p, x_f, data.inputs, ddq_f, friction)
        force_s, _ = input_forces(model, p, run.states, run.inputs, run.accelerations, friction)
        errors["force"] = relative_error_percent(force[:n], force_s[:n])
    except ScoreUnavailable as err:
        unavailable["force"] = str(err)
    return ClosedLoopScore(controller, run, names, max(n - BORDER_SAMPLES, 0), errors, unavailable)
