"""Open-loop simulation with zero-order-held inputs (section 5.3: T = 1 ms).

Sample k is the instant t_k = k T; the input row u_k is held from t_k to t_{k+1} (the D/A
converter), and the states are returned at every t_k (the A/D side samples them there). One
sample is one RK4 step function (``integrators``) and the horizon is its ``mapaccum``: a single
CasADi call, optionally compiled to native code (``compiled=True``, see ``compiled.py``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from hframe_id.models import Model
from hframe_id.simulation.compiled import evaluate, maybe_compile
from hframe_id.simulation.friction import (
    FrictionOptions,
    dynamics_function,
    sign_substeps,
    stick_slip_substeps,
)
from hframe_id.simulation.integrators import rk4_function, stable_substeps

SMOOTH = FrictionOptions()


@lru_cache(maxsize=64)
def _trajectory_function(
    model: Model,
    n_substeps: int,
    dt: float,
    n_samples: int,
    friction_model: str = "smooth",
    compiled: bool = False,
) -> ca.Function:
    """X = F(x0, U, p, s): all states after each of n_samples held-input samples."""
    step = rk4_function(dynamics_function(model, FrictionOptions(friction_model)), n_substeps, dt)
    horizon = step.mapaccum("trajectory", n_samples)
    x0, u = ca.MX.sym("x0", model.n_states), ca.MX.sym("u", model.n_inputs, n_samples)
    p, s = ca.MX.sym("p", step.size1_in(2)), ca.MX.sym("s", 2)
    flat = ca.Function(
        f"open_loop_{model.variant.replace('-', '_')}_{n_samples}",
        [x0, u, p, s], [horizon(x0, u, p, s)], ["x0", "u", "p", "s"], ["x"],
    )  # fmt: skip
    return maybe_compile(flat, compiled)


def default_substeps(
    model: Model, p: np.ndarray, dt: float, friction: FrictionOptions = SMOOTH
) -> int:
    """RK4 substeps per sample: stable for the smoothed Coulomb mode, band-resolving for
    stick-slip, as fine as the benchmark's steps for the sign law."""
    if friction.model == "smooth":
        return stable_substeps(model, p, dt, model.options.smoothing)
    if friction.model == "sign":
        return sign_substeps(model, p, dt)
    return stick_slip_substeps(model, p, dt, friction.band)


def simulate(
    model: Model,
    p: np.ndarray,
    inputs: np.ndarray,
    dt: float = 1e-3,
    x0: np.ndarray | None = None,
    n_substeps: int | None = None,
    smoothing: tuple[float, float] | None = None,
    friction: FrictionOptions | None = None,
    compiled: bool = False,
) -> np.ndarray:
    """States at the sample instants for a zero-order-held input sequence.

    Parameters
    ----------
    model : the model variant.
    p : parameter vector in ``model.parameters`` order (SI).
    inputs : (N, n_u) voltages [V]; row k is held from t_k to t_{k+1}.
    dt : sample period [s].
    x0 : initial state (default rest at the origin).
    n_substeps : RK4 substeps per sample (default: ``default_substeps``).
    smoothing : Coulomb smoothing velocities for the smooth law (default: the model's options).
    friction : friction law (default: the model's smoothed Coulomb law).
    compiled : evaluate native code built by gcc (cached on disk) instead of CasADi's VM.

    Returns
    -------
    (N + 1, n_x) states at t_0 .. t_N.
    """
    friction = friction or SMOOTH
    inputs = np.atleast_2d(np.asarray(inputs, dtype=float))
    if inputs.shape[1] != model.n_inputs:
        raise ValueError(f"inputs need {model.n_inputs} columns, got shape {inputs.shape}")
    if not dt > 0:
        raise ValueError(f"dt must be > 0 s, got {dt}")
    p = np.asarray(p, dtype=float)
    if friction.model == "smooth":
        s = smoothing or model.options.smoothing
    else:
        s = friction.band
    x0 = np.zeros(model.n_states) if x0 is None else np.asarray(x0, dtype=float)
    if n_substeps is None:
        n_substeps = (
            stable_substeps(model, p, dt, s)
            if friction.model == "smooth"
            else default_substeps(model, p, dt, friction)
        )
    trajectory = _trajectory_function(
        model, int(n_substeps), float(dt), inputs.shape[0], friction.model, bool(compiled)
    )
    (states,) = evaluate(trajectory, [x0, inputs, p, np.asarray(s, dtype=float)])
    return np.vstack([x0, states])


def outputs_of(model: Model, states: np.ndarray, inputs: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(K, n_y) the model's outputs (``Model.output_map``) at states (K, n_x) [SI] under
    inputs (N, n_u) [V] and parameters ``p`` (SI, model order): the state at t_k with the
    input held from t_k; states beyond the inputs (the final one) take the last input."""
    states = np.atleast_2d(np.asarray(states, dtype=float))
    inputs = np.atleast_2d(np.asarray(inputs, dtype=float)).reshape(-1, model.n_inputs)
    k = states.shape[0]
    held = inputs[np.minimum(np.arange(k), inputs.shape[0] - 1)]
    outputs = model.output_map.map(k)(states.T, held.T, np.repeat(np.reshape(p, (-1, 1)), k, 1))
    return np.array(outputs).T.reshape(k, -1)


@dataclass(frozen=True)
class SimulationResult:
    """Signals of one open-loop run at the sample instants (SI).

    Attributes
    ----------
    time_s : (N + 1,) sample instants t_0 .. t_N [s].
    inputs : (N, n_u) held voltages [V]; row k acts from t_k to t_{k+1}.
    states, outputs : (N + 1, n_x) and (N + 1, n_y) at t_0 .. t_N.
    state_labels, input_labels, output_labels : names with units, e.g. ``"x [m]"``.
    """

    time_s: np.ndarray
    inputs: np.ndarray
    states: np.ndarray
    outputs: np.ndarray
    state_labels: tuple[str, ...]
    input_labels: tuple[str, ...]
    output_labels: tuple[str, ...]


def run_open_loop(
    model: Model,
    p: np.ndarray,
    inputs: np.ndarray,
    dt: float = 1e-3,
    friction: FrictionOptions | None = None,
    n_substeps: int | None = None,
    compiled: bool = False,
) -> SimulationResult:
    """``simulate`` plus outputs and labelled signals (for files and plots)."""
    states = simulate(
        model, p, inputs, dt, n_substeps=n_substeps, friction=friction, compiled=compiled
    )
    outputs = outputs_of(model, states, inputs, p)
    return SimulationResult(
        time_s=np.arange(states.shape[0]) * dt,
        inputs=np.atleast_2d(np.asarray(inputs, dtype=float)),
        states=states,
        outputs=outputs,
        state_labels=tuple(s.label for s in model.states),
        input_labels=tuple(s.label for s in model.inputs),
        output_labels=tuple(s.label for s in model.outputs),
    )
