"""k-step-ahead prediction: the model's forecast k samples ahead from past data only.

For each instant t, the state at t - m is estimated from the measurements of the window
[t - m, t] alone (m = ``window``): output-error least squares over that window's initial
state, weighted by the sensors' noise std, solved by Levenberg-Marquardt for all windows at
once. The model then simulates from that state through t to t + k under the recorded inputs
(known in advance, as in MATLAB's ``predict``), and y_hat(t + k | t) is compared with y(t + k).

Why this estimator: the model has no noise model (it is an output-error fit), so a Kalman
filter would need a process-noise covariance that nothing determines; a window of past
measurements needs only its length. Assumptions: the parameters are the ones being judged;
the sensors' noise std (rig metadata) weights the channels; the window is long enough for the
state to be observable from it (hframe-8: every coordinate is measured while the lasers are
valid; past their range, or for an unmeasured idler, the Levenberg-Marquardt damping keeps
the unobservable directions near the start guess: measured positions, rigid-motion fill,
finite-difference velocities).

Cost: the sensitivity of a window's outputs to its initial state is the product of the
one-sample state-transition Jacobians A_j = d x_{j+1} / d x_j. Windows overlap, so A_j is
evaluated once per sample, at the current estimate of x_j (the window that starts at j), and
shared by every window through j (a Gauss-Newton Jacobian that is exact at convergence up to
model error; the residuals are always exact). The RK4 step and its Jacobian are compiled to
native code (cached on disk; without a C compiler CasADi's virtual machine runs them, ~20x
slower).
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from hframe_id.fitting.dataset import Dataset, state_outputs
from hframe_id.fitting.problem import output_matrix
from hframe_id.fitting.rest_state import measured_positions, measured_rates
from hframe_id.models import Model, build_model
from hframe_id.parameters import ParameterSet
from hframe_id.simulation.compiled import maybe_compile
from hframe_id.simulation.integrators import rk4_function, stable_substeps
from hframe_id.simulation.open_loop import outputs_of

#: Default window of past samples for the state estimate (the fitter's shooting interval).
DEFAULT_WINDOW = 10
#: Default prediction horizon [samples].
DEFAULT_HORIZON = 10
#: Levenberg-Marquardt iterations; the estimate stops earlier once no window's state moves by
#: more than ``STEP_TOL`` of its scale or the summed cost falls by less than ``COST_RTOL`` in an
#: iteration (on the shipped 4V x-motion, 1e-4 stops at iteration 12-14 where 20 iterations
#: change the prediction fits by < 0.01 %).
MAX_ITERATIONS = 20
STEP_TOL = 1e-6
COST_RTOL = 1e-4


@lru_cache(maxsize=16)
def _step_functions(model: Model, n_substeps: int, dt: float) -> tuple[ca.Function, ca.Function]:
    """(x, u, p, s) -> x_next and its Jacobian d x_next / d x, native where a compiler runs."""
    step = rk4_function(model.dynamics, n_substeps, dt)
    x = ca.SX.sym("x", model.n_states)
    u = ca.SX.sym("u", model.n_inputs)
    p = ca.SX.sym("p", step.size1_in(2))
    s = ca.SX.sym("s", 2)
    jacobian = ca.Function("step_jacobian", [x, u, p, s], [ca.jacobian(step(x, u, p, s), x)])
    return maybe_compile(step, True), maybe_compile(jacobian, True)


class _Windows:
    """All estimation windows of one record: start j = 0 .. W - 1, samples j .. j + m."""

    def __init__(self, model: Model, p: np.ndarray, data: Dataset, window: int, n_windows: int):
        self.model, self.p, self.data = model, p, data
        self.m, self.w = window, n_windows
        self.s = np.asarray(model.options.smoothing, dtype=float)
        n_sub = stable_substeps(model, p, data.sample_period_s, model.options.smoothing)
        step, jacobian = _step_functions(model, n_sub, data.sample_period_s)
        self.step, self.jacobian = step.map(n_windows), jacobian.map(n_windows)
        #: dy/dx: the output map where every output is a state, else its linearization (exact
        #: in x for outputs affine in the state, such as a motor current), for sensitivities
        self.c = output_matrix(model, p)
        self.of_states = bool(np.all(state_outputs(model) >= 0))
        self.starts = np.arange(n_windows)

    def outputs(self, states: np.ndarray, first: np.ndarray) -> np.ndarray:
        """(W, K, n_y) outputs of states (W, K, n_x) at samples ``first`` (W,) + 0 .. K - 1:
        y = C x where every output is a state, else the model's output map under the
        recording's inputs at those samples."""
        if self.of_states:
            return states @ self.c.T
        rows = np.minimum(first[:, None] + np.arange(states.shape[1]), len(self.data.inputs) - 1)
        flat = outputs_of(
            self.model,
            states.reshape(-1, self.model.n_states),
            self.data.inputs[rows].reshape(-1, self.model.n_inputs),
            self.p,
        )
        return flat.reshape(*states.shape[:2], -1)

    def simulate(self, x0: np.ndarray, samples: int) -> np.ndarray:
        """(W, samples + 1, n_x) states of every window from its initial state (W, n_x)."""
        states = [x0]
        for i in range(samples):
            u = self.data.inputs[self.starts + i]
            states.append(np.array(self.step(states[-1].T, u.T, self.p, self.s)).T)
        return np.stack(states, axis=1)

    def residuals(self, states: np.ndarray) -> np.ndarray:
        """(W, (m + 1) n_y) noise-weighted output errors over each window, 0 where invalid."""
        rows = self.starts[:, None] + np.arange(self.m + 1)
        error = (
            self.outputs(states[:, : self.m + 1], self.starts) - self.data.measured[rows]
        ) / self.data.noise_std
        return np.where(self.data.valid[rows], error, 0.0).reshape(self.w, -1)

    def sensitivities(self, x0: np.ndarray, states: np.ndarray) -> np.ndarray:
        """(W, (m + 1) n_y, n_x) weighted d residuals / d initial state, from A_j shared by
        the windows: x_j is the estimate of window j (the last window's trajectory beyond)."""
        reference = np.vstack([x0, states[-1, 1 : self.m]])
        count = reference.shape[0]
        u = self.data.inputs[:count]
        a = np.empty((count, self.model.n_states, self.model.n_states))
        for lo in range(0, count, self.w):
            part = reference[lo : lo + self.w]
            padded = np.vstack([part, np.repeat(part[-1:], self.w - len(part), axis=0)])
            up = u[lo : lo + self.w]
            up = np.vstack([up, np.repeat(up[-1:], self.w - len(up), axis=0)])
            flat = np.array(self.jacobian(padded.T, up.T, self.p, self.s))
            a[lo : lo + len(part)] = flat.reshape(self.model.n_states, self.w, -1).transpose(
                1, 0, 2
            )[: len(part)]
        rows = self.starts[:, None] + np.arange(self.m + 1)
        weight = np.where(self.data.valid[rows], 1.0 / self.data.noise_std, 0.0)
        phi = np.broadcast_to(np.eye(self.model.n_states), (self.w, *a.shape[1:])).copy()
        blocks = []
        for i in range(self.m + 1):
            blocks.append((self.c @ phi) * weight[:, i, :, None])
            if i < self.m:
                phi = a[self.starts + i] @ phi
        return np.concatenate(blocks, axis=1)


def estimate_states(windows: _Windows, x_guess: np.ndarray) -> np.ndarray:
    """(W, n_x) initial states of the windows by Levenberg-Marquardt from ``x_guess``."""
    x0 = x_guess.copy()
    states = windows.simulate(x0, windows.m)
    r = windows.residuals(states)
    cost = np.einsum("wi,wi->w", r, r)
    damping = np.full(windows.w, 1e-3)
    scale = np.maximum(np.abs(x0).max(axis=0), 1e-6)
    eye = np.eye(x0.shape[1])
    total = cost.sum()
    for _ in range(MAX_ITERATIONS):
        jac = windows.sensitivities(x0, states)
        hess = np.einsum("wki,wkj->wij", jac, jac)
        grad = np.einsum("wki,wk->wi", jac, r)
        diag = np.einsum("wii->wi", hess) + 1e-12 * np.einsum("wii->w", hess)[:, None] + 1e-300
        lhs = hess + damping[:, None, None] * diag[:, :, None] * eye
        step = -np.linalg.solve(lhs, grad[:, :, None])[:, :, 0]
        trial_x0 = x0 + step
        trial_states = windows.simulate(trial_x0, windows.m)
        trial_r = windows.residuals(trial_states)
        trial_cost = np.einsum("wi,wi->w", trial_r, trial_r)
        better = np.isfinite(trial_cost) & (trial_cost <= cost)
        x0[better], states[better], r[better], cost[better] = (
            trial_x0[better],
            trial_states[better],
            trial_r[better],
            trial_cost[better],
        )
        damping = np.where(better, damping / 3.0, damping * 4.0)
        total, previous = cost.sum(), total
        moved = np.max(np.abs(step[better]) / scale, initial=0.0)
        if moved < STEP_TOL or previous - total <= COST_RTOL * total:
            break
    return x0


def _state_guess(model: Model, p: np.ndarray, data: Dataset, count: int) -> np.ndarray:
    """(count, n_x) start guesses: measured positions (rigid-motion fill), finite-difference
    velocities, or a rate's measurement where a channel measures it (``measured_rates``)."""
    positions = measured_positions(model, p, data)
    velocities = np.gradient(positions, data.sample_period_s, axis=0)
    rates = measured_rates(model, data)
    velocities = np.where(np.isfinite(rates), rates, velocities)
    return np.hstack([positions, velocities])[:count]


def initial_state(params: ParameterSet, data: Dataset, window: int) -> np.ndarray:
    """(n_x,) the state at the first sample estimated from samples 0 .. ``window`` alone, as
    each prediction window's state is (output-error least squares, module docstring)."""
    model = build_model(params.variant)
    p = model.parameter_vector(params.values)
    windows = _Windows(model, p, data, window, 1)
    return estimate_states(windows, _state_guess(model, p, data, 1))[0]


def predict_ahead(
    params: ParameterSet,
    data: Dataset,
    horizon: int = DEFAULT_HORIZON,
    window: int = DEFAULT_WINDOW,
) -> np.ndarray:
    """(N, n_y) k-step-ahead predictions y_hat(t + k | t) [SI], NaN where none exists
    (the first m + k samples, whose window would start before the record).

    Parameters
    ----------
    params : the parameters judged (their model's outputs are ``data``'s channels).
    data : the recording's channels (``replay.channels``).
    horizon : k [samples], >= 1.
    window : m [samples] of past data for the state estimate, >= 1.
    """
    model = build_model(params.variant)
    p = model.parameter_vector(params.values)
    n = data.measured.shape[0]
    predicted = np.full(data.measured.shape, np.nan)
    n_windows = n - window - horizon
    if n_windows < 1:
        return predicted
    windows = _Windows(model, p, data, window, n_windows)
    x0 = estimate_states(windows, _state_guess(model, p, data, n_windows))
    states = windows.simulate(x0, window + horizon)
    last = windows.outputs(states[:, -1:], windows.starts + window + horizon)
    predicted[window + horizon :] = last[:, 0]
    return predicted
