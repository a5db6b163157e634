"""The generalized forces a model's inputs produce, measured and predicted by the inverse model.

The EMPS benchmark scores the motor force gtau vir (Simulation_EMPS.m, Script_IDIM_LS.m). For
any model, that is the part of the generalized force the inputs produce,

    F_u(x, u) = Q_act(x, u) - Q_act(x, 0)             [N or N m per actuated coordinate]

(EMPS: gtau vir; an H-frame motor: g K_t / R u), on the coordinates the inputs act on. The
inverse model predicts it from the motion alone, as IDIM does:

    F_hat(q, qdot, qddot) = M(q) (qddot - f(q, qdot, u = 0))

(EMPS: M qddot + F_v qdot + F_c sign(qdot) + F_0), with f the accelerations under the chosen
Coulomb law (``hframe_id.simulation.friction``) and no input.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from hframe_id.fitting.dataset import Dataset
from hframe_id.models import Model
from hframe_id.simulation.friction import FrictionOptions, dynamics_function
from hframe_id.validation.benchmark_filters import ScoreUnavailable, filtered_motion


@lru_cache(maxsize=32)
def actuated(model: Model) -> tuple[int, ...]:
    """Indices of the coordinates some input acts on (d Q_act / d u not structurally zero)."""
    x = ca.SX.sym("x", model.n_states)
    u = ca.SX.sym("u", model.n_inputs)
    p = ca.SX.sym("p", len(model.parameters))
    sensitivity = ca.jacobian(model.actuation(x, u, p), u)
    return tuple(
        sorted({row for row, _ in zip(*sensitivity.sparsity().get_triplet(), strict=True)})
    )


@lru_cache(maxsize=32)
def _forces(model: Model, friction_model: str) -> ca.Function:
    """(x, u, qddot, p, s) -> (F_u, F_hat) on the actuated coordinates, one sample."""
    x = ca.SX.sym("x", model.n_states)
    u = ca.SX.sym("u", model.n_inputs)
    qddot = ca.SX.sym("qddot", model.n_states // 2)
    p = ca.SX.sym("p", len(model.parameters))
    s = ca.SX.sym("s", 2)
    rows = list(actuated(model))
    produced = model.actuation(x, u, p) - model.actuation(x, ca.DM.zeros(model.n_inputs), p)
    dynamics = dynamics_function(model, FrictionOptions(friction_model))
    unforced = dynamics(x, ca.DM.zeros(model.n_inputs), p, s)[model.n_states // 2 :]
    predicted = ca.mtimes(model.mass(p), qddot - unforced)
    return ca.Function("input_forces", [x, u, qddot, p, s], [produced[rows], predicted[rows]])


def input_forces(
    model: Model,
    p: np.ndarray,
    states: np.ndarray,
    inputs: np.ndarray,
    accelerations: np.ndarray,
    friction: FrictionOptions,
) -> tuple[np.ndarray, np.ndarray]:
    """(F_u, F_hat), each (N, n_actuated): the inputs' force and the inverse model's
    prediction along a motion (states (N, n_x), inputs (N, n_u), accelerations (N, n_q))."""
    n = states.shape[0]
    function = _forces(model, friction.model).map(n)
    s = np.asarray(friction.shape(model), dtype=float)
    produced, predicted = function(states.T, inputs.T, accelerations.T, p, s)
    return np.array(produced).T, np.array(predicted).T


def measured_motion(model: Model, data: Dataset) -> tuple[np.ndarray, np.ndarray]:
    """(x_f (N, n_x), qddot_f (N, n_q)): every coordinate's measured position filtered and
    differentiated as the benchmark does (``benchmark_filters.filtered_motion``).

    Raises ``ScoreUnavailable`` when a coordinate is not measured, or not at every sample.
    """
    names = [c.name for c in model.coordinates]
    missing = [n for n in names if n not in data.names]
    if missing:
        raise ScoreUnavailable(f"coordinate(s) {', '.join(missing)} not measured")
    columns = [data.names.index(n) for n in names]
    gaps = [names[i] for i, j in enumerate(columns) if not data.valid[:, j].all()]
    if gaps:
        raise ScoreUnavailable(f"{', '.join(gaps)} not valid at every sample")
    q_f, dq_f, ddq_f = filtered_motion(data.measured[:, columns], data.sample_period_s)
    return np.hstack([q_f, dq_f]), ddq_f
