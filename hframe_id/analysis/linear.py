"""Linearization about rest: state-space matrices, poles, zeros, natural frequencies, damping.

Coulomb friction has no meaningful linearization at rest: the smoothed law F_c tanh(v / v_s)
has slope F_c / v_s at v = 0, an artefact of the smoothing, and the true law is not
differentiable there. ``linearize`` therefore excludes it (Coulomb levels set to zero) and says
so in ``LinearModel.notes``; viscous friction, back-EMF, belts and inertias are linearized
exactly. With the thesis's linear parameter files (Coulomb zero) this is the thesis's model.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import scipy.linalg

from hframe_id.models import Model, build_model
from hframe_id.parameters import ParameterSet

COULOMB_NOTE = (
    "Coulomb friction is excluded from the linearization (its levels are set to zero): "
    "it has no meaningful linearization at rest."
)


@dataclass(frozen=True)
class LinearModel:
    """xdot = A x + B u, y = C x + D u about x = 0, u = 0 (SI units)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    state_units: tuple[str, ...]
    input_units: tuple[str, ...]
    output_units: tuple[str, ...]
    notes: tuple[str, ...] = field(default_factory=tuple)

    def siso(self, input_name: str, output_name: str) -> LinearModel:
        """The single-input single-output subsystem input_name -> output_name."""
        i = _position(self.inputs, input_name, "input")
        o = _position(self.outputs, output_name, "output")
        return LinearModel(
            self.A,
            self.B[:, [i]],
            self.C[[o], :],
            self.D[[o]][:, [i]],
            self.states,
            (self.inputs[i],),
            (self.outputs[o],),
            self.state_units,
            (self.input_units[i],),
            (self.output_units[o],),
            self.notes,
        )

    def poles(self) -> np.ndarray:
        """Eigenvalues of A [rad/s], sorted by imaginary part then real part."""
        return _sorted(np.linalg.eigvals(self.A))

    def zeros(self) -> np.ndarray:
        """Invariant zeros [rad/s] of a SISO system: finite generalized eigenvalues of the
        Rosenbrock pencil [[A, B], [C, D]] - s [[I, 0], [0, 0]]."""
        if self.B.shape[1] != 1 or self.C.shape[0] != 1:
            raise ValueError("zeros() needs a SISO system; use siso(input, output) first")
        n = self.A.shape[0]
        pencil_a = np.block([[self.A, self.B], [self.C, self.D]])
        pencil_b = np.zeros_like(pencil_a)
        pencil_b[:n, :n] = np.eye(n)
        values = scipy.linalg.eigvals(pencil_a, pencil_b)
        finite = values[np.isfinite(values) & (np.abs(values) < 1e12)]
        return _sorted(finite)


def _position(names: tuple[str, ...], name: str, kind: str) -> int:
    from hframe_id.errors import ModelError

    if name not in names:
        raise ModelError(f"no {kind} named {name!r}; valid: {', '.join(names)}")
    return names.index(name)


def _sorted(values: np.ndarray) -> np.ndarray:
    cleaned = np.where(
        np.abs(values.imag) < 1e-9 * np.maximum(1, np.abs(values)), values.real, values
    )
    cleaned = np.where(np.abs(cleaned) < 1e-9, 0, cleaned)
    return np.array(sorted(cleaned, key=lambda z: (-abs(z.imag), z.real, z.imag)), dtype=complex)


def natural_frequency_and_damping(poles: np.ndarray) -> list[tuple[float, float]]:
    """(omega_n [rad/s], zeta) of each pole; a pole at 0 has omega_n = 0 and zeta = 1."""
    result = []
    for pole in poles:
        omega = float(abs(pole))
        zeta = float(-pole.real / omega) if omega > 0 else 1.0
        result.append((omega, zeta))
    return result


def linearize(params: ParameterSet, model: Model | None = None) -> LinearModel:
    """Linearize the model of a parameter set about rest (x = 0, u = 0), Coulomb excluded."""
    model = model or build_model(params.variant)
    values = dict(params.values)
    notes: tuple[str, ...] = ()
    coulomb = [
        name
        for friction in model.frictions
        for name in (friction.coulomb, friction.static)
        if name is not None
    ]
    if any(values[name] > 0 for name in coulomb):
        notes = (COULOMB_NOTE,)
    for name in coulomb:
        values[name] = 0.0
    p = model.parameter_vector(values)
    x = ca.SX.sym("x", model.n_states)
    u = ca.SX.sym("u", model.n_inputs)
    xdot = model.f(x, u, p)
    y = model.output_map(x, u, p)
    jac = ca.Function(
        "linearization",
        [x, u],
        [ca.jacobian(xdot, x), ca.jacobian(xdot, u), ca.jacobian(y, x), ca.jacobian(y, u)],
    )
    A, B, C, D = (np.array(m) for m in jac(np.zeros(model.n_states), np.zeros(model.n_inputs)))
    return LinearModel(
        A,
        B,
        C,
        D,
        tuple(s.name for s in model.states),
        tuple(s.name for s in model.inputs),
        tuple(s.name for s in model.outputs),
        tuple(s.unit for s in model.states),
        tuple(s.unit for s in model.inputs),
        tuple(s.unit for s in model.outputs),
        notes,
    )
