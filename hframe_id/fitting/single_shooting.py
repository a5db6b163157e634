"""A fit's all-window stage as an unconstrained least-squares problem (single shooting).

The unknowns are z = (each experiment's initial state along its basis
(``MultipleShooting.initial_state_bases``: every entry [SI] for a record in motion, the
rigid-mode amplitudes for one at rest), in experiment order; then the active free
log-parameters theta = ln(p / p0)). The residuals r(z) are the noise-weighted output
errors of every record simulated from its initial state (the transcription's windows
chained: continuity holds by construction), with the priors' rows;
the Jacobian is the single-shooting one the statistics read
(``GaussNewton.condensed_jacobian``). Any least-squares solver can minimise 1/2 |r(z)|^2
over it (examples/scipy_solver.py plugs in SciPy's ``least_squares``).
"""

from __future__ import annotations

import numpy as np

from hframe_id.errors import OptionError
from hframe_id.fitting.shooting import Evaluation, MultipleShooting
from hframe_id.fitting.solver import GaussNewton, SolverState


class SingleShooting:
    """Residuals and Jacobian of the stage that ``state`` starts (``ms``: its transcription).

    ``start()`` is z at ``state``, ``bounds()`` the box of z (the parameters' bounds; the
    states unbounded), ``residual(z)`` and ``jacobian(z)`` share one evaluation per point,
    and ``finish(z)`` leaves the point in ``state`` (nodes simulated from its initial states).
    """

    def __init__(self, ms: MultipleShooting, state: SolverState):
        if ms.transcription.continuity != "exact":
            raise OptionError(
                "single shooting needs one trajectory per record (continuity 'exact'), "
                f"got continuity {ms.transcription.continuity!r}"
            )
        self.ms = ms
        self.state = state
        self.smoothing = ms.problem.smoothing
        self.bases = ms.initial_state_bases  # per experiment (n_x, r)
        self.n_initial = sum(basis.shape[1] for basis in self.bases)
        self.active = state.active.copy()
        self._linearisation = GaussNewton(ms)
        self._last: tuple[bytes, Evaluation, np.ndarray] | None = None

    def start(self) -> np.ndarray:
        """z at the stage's start."""
        first = self.state.nodes[self.ms.first_window]
        amplitudes = [basis.T @ x0 for basis, x0 in zip(self.bases, first, strict=True)]
        return np.concatenate([*amplitudes, self.state.theta[self.active]])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) of z: -inf/inf for the initial states, the parameters' box."""
        problem = self.ms.problem
        n = self.n_initial
        lower = np.concatenate([np.full(n, -np.inf), problem.theta_lower[self.active]])
        upper = np.concatenate([np.full(n, np.inf), problem.theta_upper[self.active]])
        return lower, upper

    def point(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(nodes (W, n_x) [SI], theta (n_f,)) of ``z``: each record simulated from its
        initial state, the inactive parameters as in the start."""
        z = np.asarray(z, dtype=float)
        theta = self.state.theta.copy()
        theta[self.active] = z[self.n_initial :]
        nodes = self.state.nodes.copy()
        column = 0
        for basis, i in zip(self.bases, self.ms.first_window, strict=True):
            # The known part of the initial state as it is, the estimated part from z.
            r = basis.shape[1]
            known = nodes[i] - basis @ (basis.T @ nodes[i])
            nodes[i] = known + basis @ z[column : column + r]
            column += r
        known = np.zeros(self.ms.n_windows, dtype=bool)
        known[self.ms.first_window] = True
        return self.ms.fill_nodes(nodes, known, theta, self.smoothing), theta

    def _evaluated(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = np.asarray(z, dtype=float).tobytes()
        if self._last is None or self._last[0] != key:
            nodes, theta = self.point(z)
            ev = self.ms.evaluate(nodes, theta, self.smoothing)
            jac, residual, _ = self._linearisation.condensed_jacobian(ev, nodes, self.active)
            self._last = (key, residual, jac)
        return self._last[1], self._last[2]

    def residual(self, z: np.ndarray) -> np.ndarray:
        """r(z): the weighted residuals of the valid samples, then the priors' [-]."""
        return self._evaluated(z)[0]

    def jacobian(self, z: np.ndarray) -> np.ndarray:
        """dr/dz (rows as ``residual``, columns as z)."""
        return self._evaluated(z)[1]

    def finish(self, z: np.ndarray) -> None:
        """Leave the point ``z`` in the stage's state."""
        self.state.nodes, self.state.theta = self.point(z)
