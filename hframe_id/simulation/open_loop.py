"""Open-loop simulation with zero-order-held inputs (section 5.3: T = 1 ms)."""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from hframe_id.models import Model
from hframe_id.simulation.integrators import rk4_step, stable_substeps


@lru_cache(maxsize=64)
def _trajectory_function(model: Model, n_substeps: int, dt: float, n_samples: int) -> ca.Function:
    """X = F(x0, U, p, s): all states after each of n_samples held-input samples."""
    return rk4_step(model, n_substeps, dt).mapaccum("trajectory", n_samples)


def simulate(
    model: Model,
    p: np.ndarray,
    inputs: np.ndarray,
    dt: float = 1e-3,
    x0: np.ndarray | None = None,
    n_substeps: int | None = None,
    smoothing: tuple[float, float] | None = None,
) -> np.ndarray:
    """States at the sample instants for a zero-order-held input sequence.

    Parameters
    ----------
    model : the model variant.
    p : parameter vector in ``model.parameters`` order (SI).
    inputs : (N, n_u) voltages [V]; row k is held from t_k to t_{k+1}.
    dt : sample period [s].
    x0 : initial state (default rest at the origin).
    n_substeps : RK4 substeps per sample (default: ``stable_substeps`` for these parameters).
    smoothing : Coulomb smoothing velocities (default: the model's options).

    Returns
    -------
    (N + 1, n_x) states at t_0 .. t_N.
    """
    inputs = np.atleast_2d(np.asarray(inputs, dtype=float))
    if inputs.shape[1] != model.n_inputs:
        raise ValueError(f"inputs need {model.n_inputs} columns, got shape {inputs.shape}")
    p = np.asarray(p, dtype=float)
    s = smoothing or model.options.smoothing
    x0 = np.zeros(model.n_states) if x0 is None else np.asarray(x0, dtype=float)
    n = n_substeps or stable_substeps(model, p, dt, s)
    trajectory = _trajectory_function(model, int(n), float(dt), inputs.shape[0])
    states = np.array(trajectory(x0, inputs.T, p, ca.DM(s))).T
    return np.vstack([x0, states])
