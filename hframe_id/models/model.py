"""The frozen, named model every other part of hframe-id uses: f(x, u, p) -> xdot."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import casadi as ca
import numpy as np

from hframe_id.errors import ModelError
from hframe_id.models.declaration import ModelDeclaration, Output, check_system, output_expressions
from hframe_id.models.lagrange import Friction, LagrangianSystem, accelerations, mass_matrix
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
    output_map : ``ca.Function`` (x, u, p) -> y, the measured outputs (coordinates, or any
        declared ``Output`` of the state, inputs and parameters): the one output map that
        fitting, validation and simulation evaluate.
    output : ``ca.Function`` (x) -> y, the same map where no output depends on u or p (every
        coordinate output, a speed); None where one does (a motor current): use ``output_map``.
    energy : ``ca.Function`` (x, p) -> (T [J], V [J]).
    mass : ``ca.Function`` (p) -> M, the mass matrix d^2 T / dqdot^2 (constant in q here).
    actuation : ``ca.Function`` (x, u, p) -> Q_act, the generalized forces other than friction
        and the springs (motor torques) [N or N m].
    frictions : the friction-bearing coordinates and their parameters.
    declaration : the declaration the model was derived from.
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
    output_map: ca.Function
    output: ca.Function | None
    energy: ca.Function
    mass: ca.Function
    actuation: ca.Function
    frictions: tuple[Friction, ...]
    declaration: ModelDeclaration

    @property
    def n_states(self) -> int:
        """Number of states, the length of x."""
        return len(self.states)

    @property
    def n_inputs(self) -> int:
        """Number of inputs, the length of u."""
        return len(self.inputs)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the model's parameters in the order of the p vector (units in the names)."""
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


def freeze(declaration: ModelDeclaration, options: ModelOptions) -> Model:
    """Derive the equations of motion of a declared variant and wrap them as named functions.

    Only the parameters the options use are part of p (belt lengths only with
    position-dependent stiffness).
    """
    parameters = tuple(
        spec
        for spec in declaration.parameters
        if spec.required or options.position_dependent_stiffness
    )
    p_sym = {spec.name: ca.SX.sym(spec.name) for spec in parameters}
    p = ca.vertcat(*p_sym.values())
    u = ca.SX.sym("u", len(declaration.inputs))
    s = ca.SX.sym("s", 2)
    system: LagrangianSystem = declaration.lagrangian(p_sym, u, options)
    check_system(declaration, system, [p, u])
    x = ca.vertcat(system.q, system.qdot)
    xdot = ca.vertcat(system.qdot, accelerations(system, p_sym, s))
    coordinate_names = [c.name for c in system.coordinates]
    y = output_expressions(declaration, system, p_sym, u)

    dynamics = ca.Function("dynamics", [x, u, p, s], [xdot], ["x", "u", "p", "s"], ["xdot"])
    f = ca.Function(
        "f", [x, u, p], [dynamics(x, u, p, ca.DM(options.smoothing))], ["x", "u", "p"], ["xdot"]
    )
    rate_units = {"m": "m/s", "rad": "rad/s"}
    states = system.coordinates + tuple(
        Signal(f"{c.name}_dot", rate_units[c.unit], f"rate of {c.description}")
        for c in system.coordinates
    )
    outputs = tuple(
        Signal(o.name, o.unit, o.description)
        if isinstance(o, Output)
        else system.coordinates[coordinate_names.index(o)]
        for o in declaration.outputs
    )
    of_state = not ca.depends_on(y, ca.vertcat(u, p))
    return Model(
        variant=declaration.name,
        description=declaration.description,
        options=options,
        states=states,
        inputs=declaration.inputs,
        outputs=outputs,
        parameters=parameters,
        coordinates=system.coordinates,
        dynamics=dynamics,
        f=f,
        output_map=ca.Function("output_map", [x, u, p], [y], ["x", "u", "p"], ["y"]),
        output=ca.Function("output", [x], [y], ["x"], ["y"]) if of_state else None,
        energy=ca.Function(
            "energy",
            [x, p],
            [system.kinetic_energy, system.potential_energy],
            ["x", "p"],
            ["T", "V"],
        ),
        mass=ca.Function("mass", [p], [mass_matrix(system)], ["p"], ["M"]),
        actuation=ca.Function(
            "actuation", [x, u, p], [system.actuation], ["x", "u", "p"], ["Q_act"]
        ),
        frictions=system.frictions,
        declaration=declaration,
    )
