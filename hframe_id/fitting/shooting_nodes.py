"""Starting values of a multiple-shooting transcription's nodes: from the measurements
(``initial_nodes``: measured and belt-free positions, differenced or measured rates) or by
simulating from the last known node (``fill_nodes``).
"""

from __future__ import annotations

import numpy as np

from hframe_id.fitting.problem import rigid_modes
from hframe_id.fitting.rest_state import rest_state


class ShootingNodes:
    """The node-start methods of ``MultipleShooting`` (its base class). They read the
    transcription's problem, model, sizes (``nx``, ``nq``), output matrix ``c`` and
    ``output_states``, its windows (``n_windows``, ``m``, ``window_experiment``,
    ``window_start``), ``dt`` [s], the compiled state kernel ``native[False]`` and
    ``substep_plan``; ``initial_nodes`` sets ``measured_positions``, ``rigid_positions`` and
    ``measured_usable`` (per experiment, (N, n_q) [SI] and (N,) all outputs valid)."""

    def initial_nodes(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Node states from the measurements, and a per-sample velocity estimate.

        Positions: measured coordinates where valid; the others (and invalid samples) from
        the belt-free (rigid) motion fitted to the measured ones, weighted by their noise.
        Velocities: central differences of the rigid-motion positions (encoder-dominated),
        or a rate's measurement (a tachometer) where valid; a coordinate measured only
        through its rate takes that rate's integral from 0 as its position; a record's first
        node at rest takes the belt-free positions and no speed (with ``rest_start``
        "replay", the replay's rest state, ``fitting.rest_state.rest_state``). Outputs that are
        other functions of the state (a motor current) do not enter. Returns nodes (W, n_x)
        and the velocity estimate (W, M + 1, n_q).
        """
        modes = rigid_modes(self.model, p)
        springs = modes.shape[1] < self.nq
        cq = self.c[:, : self.nq]
        index = self.output_states
        position = (index >= 0) & (index < self.nq)
        rate = index >= self.nq
        integrated = np.zeros(self.nq, dtype=bool)
        integrated[index[rate] - self.nq] = True
        integrated[index[position]] = False
        nodes = np.zeros((self.n_windows, self.nx))
        velocity = np.zeros((self.n_windows, self.m + 1, self.nq))
        self.measured_positions: list[np.ndarray] = []
        self.rigid_positions: list[np.ndarray] = []
        self.measured_usable: list[np.ndarray] = []
        for e, exp in enumerate(self.problem.experiments):
            n = exp.n_samples
            weights = exp.valid / self.problem.recording_std[e] * position
            y = np.where(exp.valid, exp.measured, 0.0)
            rigid = self._rigid_fit(cq @ modes, modes, y, weights)
            positions = rigid.copy()
            for j in np.flatnonzero(position):
                positions[exp.valid[:, j], index[j]] = exp.measured[exp.valid[:, j], j]
            rates = np.gradient(rigid, self.dt, axis=0) if n > 1 else np.zeros_like(rigid)
            for j in np.flatnonzero(rate):
                rates[exp.valid[:, j], index[j] - self.nq] = exp.measured[exp.valid[:, j], j]
            for i in np.flatnonzero(integrated):
                steps = 0.5 * (rates[1:, i] + rates[:-1, i]) * self.dt
                rigid[:, i] = positions[:, i] = np.concatenate([[0.0], np.cumsum(steps)])
            self.measured_positions.append(positions)
            self.rigid_positions.append(rigid)
            self.measured_usable.append(np.all(exp.valid, axis=1))
            windows = np.flatnonzero(self.window_experiment == e)
            k0 = self.window_start[windows]
            nodes[windows, : self.nq] = positions[k0]
            nodes[windows, self.nq :] = rates[k0]
            velocity[windows] = rates[np.minimum(k0[:, None] + np.arange(self.m + 1), n - 1)]
            if exp.at_rest and self.transcription.rest_start == "replay":
                nodes[windows[0]] = rest_state(self.model, p, exp)
            elif exp.at_rest:
                nodes[windows[0], self.nq :] = 0.0
                if springs:  # unstretched at rest (``MultipleShooting.node_projector``)
                    nodes[windows[0], : self.nq] = rigid[0]
        return nodes, velocity

    def _rigid_fit(self, design, modes, y, weights) -> np.ndarray:
        """(N, n_q) belt-free positions: per sample, the rigid-mode amplitudes fitted to the
        outputs y (N, n_y) [SI] with weights (N, n_y) [1/SI] by least squares; a sample with
        fewer valid outputs than modes keeps the previous sample's (rest at the start)."""
        rigid = np.zeros((len(y), self.nq))
        enough = np.count_nonzero(weights, axis=1) >= modes.shape[1]
        patterns, group = np.unique(weights, axis=0, return_inverse=True)
        for g, w in enumerate(patterns):
            ks = np.flatnonzero((group.ravel() == g) & enough)
            if ks.size:
                # One solve per validity pattern, its samples as right-hand sides (the
                # same numbers as sample by sample, 50x faster).
                coef, *_ = np.linalg.lstsq(design * w[:, None], (y[ks] * w).T, rcond=None)
                coef = np.ascontiguousarray(coef.T)[:, :, None]
                rigid[ks] = np.matmul(modes, coef)[:, :, 0]
        for k in np.flatnonzero(~enough):
            if k > 0:
                rigid[k] = rigid[k - 1]
        return rigid

    def fill_nodes(
        self,
        nodes: np.ndarray,
        known: np.ndarray,
        theta: np.ndarray,
        smoothing: tuple[float, float],
    ) -> np.ndarray:
        """Nodes of the windows not ``known`` (bool per window), by simulating forward from
        the last known node before them (or from rest at the measured start positions)."""
        p = self.problem.parameters(theta)
        n_sub = self.substep_plan(p, smoothing)["stiff"]
        nodes = nodes.copy()
        known = known.copy()
        for e, exp in enumerate(self.problem.experiments):
            idx = np.flatnonzero(self.window_experiment == e)
            if not idx.size:  # none of its windows in this view (a record that never moves)
                continue
            if not known[idx[0]]:
                # The first node as given: measured positions, and no speed for a record at
                # rest (``Dataset.at_rest``), the measured rates for one in motion.
                if exp.at_rest:
                    nodes[idx[0], self.nq :] = 0.0
                known[idx[0]] = True
            i = 0
            while i < idx.size:
                if known[idx[i]]:
                    i += 1
                    continue
                j = i
                while j < idx.size and not known[idx[j]]:
                    j += 1
                # Windows idx[i:j] are unknown: simulate from the previous window's node.
                k0 = self.window_start[idx[i - 1]]
                x0 = nodes[idx[i - 1]]
                k1 = self.window_start[idx[j - 1]]
                states = self._simulate(x0, exp.inputs[k0:k1], p, smoothing, n_sub)
                for w in idx[i:j]:
                    nodes[w] = states[self.window_start[w] - k0]
                i = j
        return nodes

    def _simulate(self, x0, inputs, p, smoothing, n_sub: int) -> np.ndarray:
        """(N + 1, n_x) states from ``x0`` under held ``inputs`` (N, n_u) [V] with ``n_sub``
        substeps per sample: the compiled state kernel run as one window of N samples (the
        same numbers as ``open_loop.simulate``, 6x faster and nothing built per length)."""
        from hframe_id.simulation.open_loop import simulate

        kernel = self.native[False]
        if kernel is None:
            return simulate(
                self.model, p, inputs, self.dt, x0=x0, n_substeps=n_sub, smoothing=smoothing
            )
        arrays = {
            "x0": np.array(x0, dtype=float),
            "u": np.ascontiguousarray(inputs, dtype=float),
            "p": np.ascontiguousarray(p, dtype=float),
            "s": np.array(smoothing, dtype=float),
            "xs": np.empty((len(inputs), self.nx)),
        }
        if kernel(arrays, self.dt / n_sub, n_sub, len(inputs), 1, 1) != 0:
            raise FloatingPointError("simulation failed")
        return np.vstack([arrays["x0"], arrays["xs"]])
