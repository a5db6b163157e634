"""The frozen, named model every other part of hframe-id uses: f(x, u, p) -> xdot."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import casadi as ca
import numpy as np

from hframe_id.errors import ModelError
from hframe_id.models.lagrange import LagrangianSystem, accelerations, mass_matrix
from hframe_id.models.options import ModelOptions
from hframe_id.models.spec import ParameterSpec, Signal


@dataclass(frozen=True)
class Model:
    """A model variant derived by Lagrange's equations, with named signals and parameters.

    The state is x = [q; qdot] (all generalized coordinates, then their rates).

    Attributes
    ----------
    dynamics : ``ca.Function`` (x, u, p, s) -> xdot, with s = (v_s linear [m/s], v_s angular
        [rad/s]) the Coulomb smoothing velocities as a run-time input (used for continuation).
    f : ``ca.Function`` (x, u, p) -> xdot with s fixed at ``options.smoothing``.
    output : ``ca.Function`` (x) -> y, the measured outputs.
    energy : ``ca.Function`` (x, p) -> (T [J], V [J]).
    """

    variant: str
    description: str
    options: ModelOptions
    states: tuple[Signal, ...]
    inputs: tuple[Signal, ...]
    outputs: tuple[Signal, ...]
    parameters: tuple[ParameterSpec, ...]
    coordinates: tuple[Signal, ...]
    dynamics: ca.Function
    f: ca.Function
    output: ca.Function
    energy: ca.Function
    mass: ca.Function

    @property
    def n_states(self) -> int:
        return len(self.states)

    @property
    def n_inputs(self) -> int:
        return len(self.inputs)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(spec.name for spec in self.parameters)

    def parameter_vector(self, values: Mapping[str, float]) -> np.ndarray:
        """Order SI parameter values (by name) as the model's p vector."""
        missing = [name for name in self.parameter_names if name not in values]
        if missing:
            raise ModelError(f"{self.variant}: missing parameter(s) {', '.join(missing)}")
        return np.array([float(values[name]) for name in self.parameter_names])

    def index(self, kind: str, name: str) -> int:
        """Index of a named ``"state"``, ``"input"``, ``"output"`` or ``"parameter"``."""
        names = {
            "state": [s.name for s in self.states],
            "input": [s.name for s in self.inputs],
            "output": [s.name for s in self.outputs],
            "parameter": list(self.parameter_names),
        }[kind]
        if name not in names:
            raise ModelError(
                f"{self.variant} has no {kind} named {name!r}; valid: {', '.join(names)}"
            )
        return names.index(name)


def freeze(
    variant: str,
    description: str,
    options: ModelOptions,
    parameters: tuple[ParameterSpec, ...],
    inputs: tuple[Signal, ...],
    output_names: tuple[str, ...],
    build_lagrangian,
) -> Model:
    """Derive the equations of motion of a variant and wrap them as named CasADi functions."""
    p_sym = {spec.name: ca.SX.sym(spec.name) for spec in parameters}
    p = ca.vertcat(*p_sym.values())
    u = ca.SX.sym("u", len(inputs))
    s = ca.SX.sym("s", 2)
    system: LagrangianSystem = build_lagrangian(p_sym, u, options)
    x = ca.vertcat(system.q, system.qdot)
    xdot = ca.vertcat(system.qdot, accelerations(system, p_sym, s))
    coordinate_names = [c.name for c in system.coordinates]
    y = ca.vertcat(*(system.q[coordinate_names.index(name)] for name in output_names))

    dynamics = ca.Function("dynamics", [x, u, p, s], [xdot], ["x", "u", "p", "s"], ["xdot"])
    f = ca.Function(
        "f", [x, u, p], [dynamics(x, u, p, ca.DM(options.smoothing))], ["x", "u", "p"], ["xdot"]
    )
    rate_units = {"m": "m/s", "rad": "rad/s"}
    states = system.coordinates + tuple(
        Signal(f"{c.name}_dot", rate_units[c.unit], f"rate of {c.description}")
        for c in system.coordinates
    )
    outputs = tuple(system.coordinates[coordinate_names.index(n)] for n in output_names)
    return Model(
        variant=variant,
        description=description,
        options=options,
        states=states,
        inputs=inputs,
        outputs=outputs,
        parameters=parameters,
        coordinates=system.coordinates,
        dynamics=dynamics,
        f=f,
        output=ca.Function("output", [x], [y], ["x"], ["y"]),
        energy=ca.Function(
            "energy",
            [x, p],
            [system.kinetic_energy, system.potential_energy],
            ["x", "p"],
            ["T", "V"],
        ),
        mass=ca.Function("mass", [p], [mass_matrix(system)], ["p"], ["M"]),
    )
