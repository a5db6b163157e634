"""Closed-loop simulation of a declared controller on any model, driven by a recording's signals.

The sample's timing is the declaration's (``hframe_id.control.declaration``): outputs and
references read at t_k, the law, the delay, the saturation, the disturbance added, the plant
integrated over the sample with that input held.

The references and disturbances are the recording's signals read at t_k = t_0 + k T by linear
interpolation on its time stamps, as Simulink's Repeating Sequence blocks feed the EMPS
benchmark's reference and pulses: a controller whose period T differs from the recording's runs
on its own clock, as the benchmark's model does, and the run has floor(duration / T) + 1
samples. Sample k of the run is compared with sample k of the recording (the benchmark's
scripts do the same).

One sample (law, delay queue, saturation, disturbance, ``n_substeps`` RK4 steps of the plant)
is one CasADi SX function; the horizon is its ``mapaccum``: one call for the whole run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from hframe_id.control.declaration import ControllerDeclaration, traced_law
from hframe_id.errors import ControllerError
from hframe_id.models import Model
from hframe_id.recordings.recording import Recording
from hframe_id.simulation.compiled import evaluate
from hframe_id.simulation.friction import FrictionOptions, dynamics_function
from hframe_id.simulation.integrators import rk4_expression
from hframe_id.simulation.open_loop import default_substeps

#: A run has diverged where a simulated output exceeds this many times the largest magnitude
#: the recording measured on that channel (or a state is not finite): an unstable loop.
DIVERGENCE_FACTOR = 1e3


def check_fits(controller: ControllerDeclaration, model: Model, recording: Recording) -> None:
    """Raise ``ControllerError`` (one line naming the controller and the item) unless the
    controller drives every input of ``model``, reads outputs it has (functions of the state
    alone: ``Model.output``), and reads signals ``recording`` holds, with a value at every
    sample."""
    where = controller.where
    inputs = [s.name for s in model.inputs]
    if sorted(controller.command_names) != sorted(inputs):
        raise ControllerError(
            f"{where} computes {list(controller.command_names)}, but model {model.variant} "
            f"takes inputs {inputs}"
        )
    outputs = [s.name for s in model.outputs]
    if model.output is None:
        raise ControllerError(
            f"{where}: model {model.variant} has an output that depends on its inputs or "
            f"parameters (outputs: {', '.join(outputs)}); a closed loop reads outputs that are "
            "functions of the state alone"
        )
    for name in controller.measured:
        if name not in outputs:
            raise ControllerError(
                f"{where} reads output {name!r}, which model {model.variant} does not have "
                f"(outputs: {', '.join(outputs)})"
            )
    for signal in controller.references:
        if signal.name not in recording.signal_names:
            held = ", ".join(recording.signal_names) or "none"
            raise ControllerError(
                f"{where} reads reference {signal.name!r}, which {recording.name()} does not "
                f"hold (signals: {held})"
            )
    for name in [s.name for s in controller.references] + disturbances_held(controller, recording):
        values = recording.signals[:, recording.signal_names.index(name)]
        if not np.isfinite(values).all():
            raise ControllerError(
                f"{where}: signal {name!r} of {recording.name()} has "
                f"{int(np.count_nonzero(~np.isfinite(values)))} samples without a value"
            )


def disturbances_held(controller: ControllerDeclaration, recording: Recording) -> list[str]:
    """The declared disturbance signals that ``recording`` holds (the others add nothing)."""
    return [s for _, s in controller.disturbances if s in recording.signal_names]


@lru_cache(maxsize=16)
def loop_step(
    model: Model,
    controller: ControllerDeclaration,
    n_substeps: int,
    dt: float,
    friction_model: str = "smooth",
) -> ca.Function:
    """F(z, r, w, p, s, g) -> (z_next, u, qddot, c): one sample of controller and plant.

    z = [x; controller states; commands waiting out the delay (oldest first)], r the
    references at t_k, w the disturbances at t_k (one per model input, 0 where none), g the
    gains; u is the plant input over [t_k, t_{k+1}) [model input units], qddot the plant's
    accelerations at t_k under it, c the commands the law computed at t_k.
    """
    law = traced_law(controller, dt, f"in its law at the loop's period ({dt:g} s)")
    n_x, n_u = model.n_states, model.n_inputs
    n_z, delay = law.size1_in(2), controller.delay_samples
    z = ca.SX.sym("z", n_x + n_z + delay * n_u)
    r = ca.SX.sym("r", law.size1_in(1))
    w = ca.SX.sym("w", n_u)
    p = ca.SX.sym("p", len(model.parameters))
    s = ca.SX.sym("s", 2)
    g = ca.SX.sym("g", law.size1_in(3))
    # Element lists, not slices: CasADi gives a 1-by-0 (not 0-by-1) slice past a 1-vector's end.
    elements = ca.vertsplit(z)
    x, memory = ca.vertcat(*elements[:n_x]), ca.vertcat(*elements[n_x : n_x + n_z])
    queue = elements[n_x + n_z :]
    outputs = [o.name for o in model.outputs]
    y = model.output(x)
    measured = ca.vertcat(*(y[outputs.index(name)] for name in controller.measured))
    c, memory_next = law(measured, r, memory, g)
    inputs = [i.name for i in model.inputs]
    commands = ca.vertcat(*(c[controller.command_names.index(name)] for name in inputs))
    if delay:
        held, queue_next = ca.vertcat(*queue[:n_u]), ca.vertcat(*queue[n_u:], commands)
    else:
        held, queue_next = commands, ca.SX(0, 1)
    disturbed = {command for command, _ in controller.disturbances}
    applied = []
    for i, name in enumerate(inputs):
        lower, upper = controller.limit(name)
        value = held[i] if math.isinf(lower) else ca.fmin(ca.fmax(held[i], lower), upper)
        applied.append(value + w[i] if name in disturbed else value)
    u = ca.vertcat(*applied)
    dynamics = dynamics_function(model, FrictionOptions(friction_model))
    qddot = dynamics(x, u, p, s)[n_x // 2 :]
    x_next = rk4_expression(dynamics, x, u, p, s, n_substeps, dt)
    return ca.Function(
        "loop_step",
        [z, r, w, p, s, g],
        [ca.vertcat(x_next, memory_next, queue_next), u, qddot, c],
        ["z", "r", "w", "p", "s", "g"],
        ["z_next", "u", "qddot", "c"],
    )


@lru_cache(maxsize=16)
def loop_horizon(
    model: Model,
    controller: ControllerDeclaration,
    n_substeps: int,
    dt: float,
    n_samples: int,
    friction_model: str = "smooth",
) -> ca.Function:
    """H(z0, R, W, p, s, g) -> (Z, U, QDDOT, C) over ``n_samples`` samples (one call)."""
    step = loop_step(model, controller, n_substeps, dt, friction_model)
    horizon = step.mapaccum("loop", n_samples)
    symbols = [
        ca.MX.sym(name, step.size1_in(i), n_samples if name in ("r", "w") else 1)
        for i, name in enumerate(step.name_in())
    ]
    return ca.Function(
        "loop_horizon", symbols, horizon.call(symbols), step.name_in(), step.name_out()
    )


@dataclass(frozen=True)
class LoopResult:
    """Signals of one closed-loop run at the controller's sample instants (SI).

    Attributes
    ----------
    time_s : (N,) t_k = t_0 + k T [s].
    states : (N, n_x) plant states at t_k.
    accelerations : (N, n_q) plant accelerations at t_k under the input applied from t_k.
    inputs : (N, n_u) plant inputs over [t_k, t_{k+1}) in model input order: the delayed,
        saturated commands plus the disturbances.
    commands : (N, n_c) the law's commands at t_k, in the controller's order.
    references : (N, n_r) the references read at t_k.
    sample_period_s : T [s].
    n_substeps : RK4 substeps per sample.
    friction : the plant's Coulomb friction law.
    disturbances : the recording signals added to the plant inputs.
    diverged_at_s : the first t_k at which the run diverged (``DIVERGENCE_FACTOR``), else None.
    """

    time_s: np.ndarray
    states: np.ndarray
    accelerations: np.ndarray
    inputs: np.ndarray
    commands: np.ndarray
    references: np.ndarray
    sample_period_s: float
    n_substeps: int
    friction: FrictionOptions
    disturbances: tuple[str, ...]
    diverged_at_s: float | None

    @property
    def stable(self) -> bool:
        """Whether the run stayed finite and within range (``DIVERGENCE_FACTOR``)."""
        return self.diverged_at_s is None


def _read(recording: Recording, name: str, times: np.ndarray) -> np.ndarray:
    """A recording signal at ``times`` [s], by linear interpolation on its time stamps."""
    values = recording.signals[:, recording.signal_names.index(name)]
    return np.interp(times, recording.time_s, values)


def _diverged(model: Model, recording: Recording, time_s: np.ndarray, states: np.ndarray):
    """The first t_k of a non-finite state or an output beyond ``DIVERGENCE_FACTOR`` x the
    largest magnitude the recording measured on it; None if there is none."""
    bad = ~np.isfinite(states).all(axis=1)
    outputs = np.array(model.output.map(states.shape[0])(states.T)).T
    for j, signal in enumerate(model.outputs):
        if signal.name in recording.output_names:
            column = recording.outputs[:, recording.output_names.index(signal.name)]
            scale = np.nanmax(np.abs(column), initial=0.0)
            if scale > 0:
                with np.errstate(invalid="ignore"):
                    bad |= np.abs(outputs[:, j]) > DIVERGENCE_FACTOR * scale
    hits = np.flatnonzero(bad)
    return float(time_s[hits[0]]) if hits.size else None


def _check_commands(
    controller: ControllerDeclaration, time_s: np.ndarray, states: np.ndarray, commands
) -> None:
    """Raise ``ControllerError`` at the first t_k where the law computed a command that is
    not a number or infinite from a finite plant state: the law's fault, not the plant's
    (the saturation turned a NaN into its lower limit, and the run went on as data)."""
    commands = np.asarray(commands, dtype=float)
    bad = np.flatnonzero(~np.isfinite(commands).all(axis=1) & np.isfinite(states).all(axis=1))
    if bad.size:
        k = int(bad[0])
        j = int(np.flatnonzero(~np.isfinite(commands[k]))[0])
        raise ControllerError(
            f"{controller.where}: the law computed {controller.command_names[j]} = "
            f"{commands[k, j]:g} at t = {time_s[k] - time_s[0]:g} s, from a finite plant state"
        )


def simulate_loop(
    model: Model,
    p: np.ndarray,
    controller: ControllerDeclaration,
    recording: Recording,
    x0: np.ndarray,
    friction: FrictionOptions | None = None,
    n_substeps: int | None = None,
) -> LoopResult:
    """Run ``controller`` on ``model`` with ``recording``'s references and disturbances.

    Parameters
    ----------
    model : the plant.
    p : parameter vector in ``model.parameters`` order (SI).
    controller : the declared controller (checked against model and recording here).
    recording : holds the references, any disturbances, and the time base.
    x0 : (n_x,) plant state at t_0 (the controller's memory starts at zero).
    friction : the plant's Coulomb friction law (default: the model's smoothed one).
    n_substeps : RK4 substeps per sample (default: ``default_substeps`` for the law).
    """
    check_fits(controller, model, recording)
    friction = friction or FrictionOptions()
    p = np.asarray(p, dtype=float)
    dt = controller.sample_period(recording)
    n = n_substeps or default_substeps(model, p, dt, friction)
    duration = float(recording.time_s[-1] - recording.time_s[0])
    n_samples = math.floor(duration / dt + 1e-9) + 1
    time_s = recording.time_s[0] + dt * np.arange(n_samples)
    references = np.column_stack(
        [_read(recording, s.name, time_s) for s in controller.references]
        or [np.empty((n_samples, 0))]
    )
    disturbances = np.zeros((n_samples, model.n_inputs))
    inputs = [s.name for s in model.inputs]
    for command, signal in controller.disturbances:
        if signal in recording.signal_names:
            disturbances[:, inputs.index(command)] += _read(recording, signal, time_s)
    horizon = loop_horizon(model, controller, int(n), float(dt), n_samples, friction.model)
    n_extra = horizon.size1_in(0) - model.n_states
    z0 = np.concatenate([np.asarray(x0, dtype=float), np.zeros(n_extra)])
    z, u, qddot, c = evaluate(
        horizon,
        [
            z0,
            references,
            disturbances,
            p,
            np.asarray(friction.shape(model), dtype=float),
            controller.gain_vector(),
        ],
    )
    states = np.vstack([z0, z[:-1]])[:, : model.n_states]
    _check_commands(controller, time_s, states, c)
    return LoopResult(
        time_s=time_s,
        states=states,
        accelerations=qddot,
        inputs=u,
        commands=c,
        references=references,
        sample_period_s=dt,
        n_substeps=int(n),
        friction=friction,
        disturbances=tuple(disturbances_held(controller, recording)),
        diverged_at_s=_diverged(model, recording, time_s, states),
    )
