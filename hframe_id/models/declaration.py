"""What a model variant is, in one place: the declaration every part of hframe-id reads.

A declaration holds the variant's coordinates, inputs, measured outputs (coordinates, or any
signal that is a function of the state, inputs and parameters: ``Output``), parameters with units,
its Lagrangian description (energies, actuation, friction-bearing coordinates; derived into
equations of motion by ``hframe_id.models.lagrange``), its reference parameter file and the
table it comes from, and which parameters a fit holds by default. The simulator, stick-slip
friction, the fitter, its report, linearization and export all take what they need from here
(through the derived ``Model``), so a new variant is one declaration: the thesis's three in
``one_axis.py``, ``hframe20.py``, ``hframe8.py``, a user's in a model file
(``hframe_id.models.user``, docs/custom-models.md).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca

from hframe_id.errors import ModelError
from hframe_id.models.lagrange import LagrangianSystem
from hframe_id.models.options import ModelOptions
from hframe_id.models.spec import ParameterSpec, Signal

#: (symbols by parameter name, input vector u, options) -> the variant's Lagrangian system.
LagrangianBuilder = Callable[[dict[str, ca.SX], ca.SX, ModelOptions], LagrangianSystem]

#: Units a generalized coordinate may have (its rate and the Coulomb smoothing follow from it).
COORDINATE_UNITS = ("m", "rad")
#: Fit options a declaration may set (``fit_defaults``).
FIT_DEFAULT_KEYS = ("shooting_interval", "continuity")
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_-]*$")
_SYMBOL = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")

#: (q, qdot, u, p), each the declared names' CasADi symbols -> the output's value (a scalar
#: expression or a number).
OutputFunction = Callable[..., Any]


@dataclass(frozen=True)
class Output:
    """A measured signal that is not a coordinate: y = function(q, qdot, u, p), in ``unit``.

    ``function`` is called once, symbolically, with the same name-to-symbol maps as a model
    file's ``equations`` (``q``, ``qdot``, ``u``, ``p``); the output is then one CasADi
    expression in the graph of the dynamics, so a fit's Jacobians are exact. Examples: a
    tachometer, ``Output("speed", "rad/s", "tachometer", lambda q, qd, u, p: qd["theta"])``; a
    motor current (g V - K_e w) / R [A]. ``noise_std`` [``unit``] is the sensor's noise std,
    the channel's weight in a fit unless the recording's rig metadata declare their own
    (``noise_std_<name>``) or the fit is told (``channel_std``, ``--noise auto``).
    """

    name: str
    unit: str
    description: str
    function: OutputFunction
    noise_std: float | None = None

    @property
    def label(self) -> str:
        """Name with unit, e.g. ``"speed [rad/s]"``."""
        return f"{self.name} [{self.unit}]"


@dataclass(frozen=True)
class ModelDeclaration:
    """A model variant, declared once.

    Attributes
    ----------
    name : variant name used in files and on the command line, e.g. ``"hframe-8"``.
    description : one line, with the thesis chapter or the source of the model.
    parameters : every parameter a parameter file of the variant may hold, with units.
    coordinates : generalized coordinates q (unit ``"m"`` or ``"rad"``).
    inputs : commanded inputs u, with units.
    outputs : the measured outputs, in the order of the output vector y: names of
        coordinates (y_j = q_i), or ``Output`` declarations (any function of q, qdot, u, p).
    lagrangian : builds the energies, actuation and friction of the variant.
    reference_file : the variant's reference parameter file (the start of a fit, the column
        a fit report compares with), or None.
    reference_label : where the reference values come from, e.g. ``"Table 4.1 + 4.2"``.
    fixed : parameters a fit holds by default because they are measured, not identified
        (geometry, motor data sheet), taken as exact.
    held : parameters a fit holds by default because the outputs do not determine them; their
        values are uncertain and enter the intervals with a prior (consider covariance).
    source : where the declaration lives (module or file), for error messages.
    model_file : the user's model file it was loaded from (``--model-file``), else None;
        parameter files of the model name it so that readers can load the model.
    fit_defaults : how ``hframe-id fit`` transcribes this model's data unless the command
        line says otherwise: ``shooting_interval`` (samples) and ``continuity`` (``"exact"``
        or ``"none"``, see ``hframe_id.fitting.FitOptions``). A plant whose open-loop
        simulation drifts (an integrator under closed-loop control) is fitted on short
        independent horizons.
    nests_in : the variant that holds this one as a limit, with one parameter more (hframe-8
        in hframe-8-current-limit: I_max -> infinity), or None. A fit tries that variant as
        well and keeps the one the data choose (``hframe_id.fitting.structure_choice``).
    """

    name: str
    description: str
    parameters: tuple[ParameterSpec, ...]
    coordinates: tuple[Signal, ...]
    inputs: tuple[Signal, ...]
    outputs: tuple[str | Output, ...]
    lagrangian: LagrangianBuilder
    reference_file: Path | None = None
    reference_label: str = ""
    fixed: tuple[str, ...] = ()
    held: tuple[str, ...] = ()
    source: str = "hframe_id"
    model_file: Path | None = None
    fit_defaults: tuple[tuple[str, Any], ...] = ()
    nests_in: str | None = None

    def __post_init__(self) -> None:
        check_declaration(self)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the model's parameters, in declaration order (the order of p)."""
        return tuple(spec.name for spec in self.parameters)

    @property
    def output_names(self) -> tuple[str, ...]:
        """Names of the outputs, in the order of y."""
        return tuple(o.name if isinstance(o, Output) else o for o in self.outputs)

    def output_noise_std(self, name: str) -> float | None:
        """The sensor noise std [output unit] an ``Output`` declares, else None (coordinates:
        the rig's sensors say)."""
        for output in self.outputs:
            if isinstance(output, Output) and output.name == name:
                return output.noise_std
        return None

    def default_free(self) -> tuple[str, ...]:
        """Parameters a fit estimates unless told otherwise: all but ``fixed`` and ``held``."""
        return tuple(n for n in self.parameter_names if n not in self.fixed + self.held)


def _fail(declaration: ModelDeclaration, message: str) -> None:
    raise ModelError(f"{declaration.source}: model {declaration.name!r}: {message}")


def _check_unique(declaration: ModelDeclaration, what: str, names: list[str]) -> None:
    seen: set[str] = set()
    for name in names:
        if name in seen:
            _fail(declaration, f"{what} {name!r} is declared twice")
        seen.add(name)


def check_name(name: Any, what: str, error: type[ModelError]) -> None:
    """A declared model's or controller's name: a letter, then letters, digits, '-' and '_'.
    Raises ``error`` starting with ``what`` (the source and the kind of name)."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise error(
            f"{what} {name!r} must start with a letter and hold only letters, digits, '-' and '_'"
        )


def check_declaration(declaration: ModelDeclaration) -> None:
    """Check the parts of a declaration that need no derivation (names, units, references).

    Raises ``ModelError`` naming the source and the offending item.
    """
    check_name(declaration.name, f"{declaration.source}: model name", ModelError)
    if not declaration.coordinates:
        _fail(declaration, "declares no coordinates")
    if not declaration.outputs:
        _fail(declaration, "declares no outputs")
    symbols = [
        ("coordinate", declaration.coordinates),
        ("input", declaration.inputs),
        ("parameter", declaration.parameters),
    ]
    for what, items in symbols:
        for item in items:
            if not isinstance(item.name, str) or not _SYMBOL.match(item.name):
                _fail(declaration, f"{what} name {item.name!r} is not an identifier")
            if not isinstance(item.unit, str) or not item.unit.strip():
                _fail(declaration, f"{what} {item.name!r} has no unit (use '-' if dimensionless)")
        _check_unique(declaration, what, [item.name for item in items])
    for coordinate in declaration.coordinates:
        if coordinate.unit not in COORDINATE_UNITS:
            _fail(
                declaration,
                f"coordinate {coordinate.name!r} has unit {coordinate.unit!r}; a generalized "
                f"coordinate is a position in {' or '.join(COORDINATE_UNITS)}",
            )
    _check_outputs(declaration)
    for key, _ in declaration.fit_defaults:
        if key not in FIT_DEFAULT_KEYS:
            _fail(
                declaration,
                f"fit default {key!r} is not one of {', '.join(FIT_DEFAULT_KEYS)}",
            )
    names = declaration.parameter_names
    for what, listed in (("fixed", declaration.fixed), ("held", declaration.held)):
        for name in listed:
            if name not in names:
                _fail(declaration, f"{what} parameter {name!r} is not declared")
    if declaration.reference_file is not None and not declaration.reference_file.is_file():
        _fail(declaration, f"reference parameter file {declaration.reference_file} does not exist")


def _check_outputs(declaration: ModelDeclaration) -> None:
    """Outputs are coordinate names or ``Output`` declarations with a unit, a function and a
    positive noise std if any; no name twice, no ``Output`` named like a coordinate."""
    coordinates = [c.name for c in declaration.coordinates]
    for output in declaration.outputs:
        if isinstance(output, str):
            if output not in coordinates:
                _fail(
                    declaration,
                    f"output {output!r} is not a coordinate ({', '.join(coordinates)}); declare "
                    f"any other measured signal as Output({output!r}, unit, description, "
                    "function)",
                )
            continue
        if not isinstance(output, Output):
            _fail(declaration, f"output {output!r} is neither a coordinate name nor an Output")
        if not isinstance(output.name, str) or not _SYMBOL.match(output.name):
            _fail(declaration, f"output name {output.name!r} is not an identifier")
        if output.name in coordinates:
            _fail(
                declaration,
                f"output {output.name!r} has the name of a coordinate; list the coordinate's "
                f"name itself in outputs",
            )
        if not isinstance(output.unit, str) or not output.unit.strip():
            _fail(declaration, f"output {output.name!r} has no unit (use '-' if dimensionless)")
        if not callable(output.function):
            _fail(declaration, f"output {output.name!r}: function must be callable (q, qdot, u, p)")
        std = output.noise_std
        if std is not None and not (
            isinstance(std, int | float) and not isinstance(std, bool) and 0 < std < math.inf
        ):
            _fail(
                declaration,
                f"output {output.name!r}: noise_std must be > 0 and finite, got {std!r}",
            )
    _check_unique(declaration, "output", list(declaration.output_names))


def output_expressions(
    declaration: ModelDeclaration,
    system: LagrangianSystem,
    parameters: Mapping[str, ca.SX],
    u: ca.SX,
) -> ca.SX:
    """The output vector y (SX, n_y) of a declaration on the symbols of its derived system:
    a coordinate output is q_i, an ``Output`` its function of (q, qdot, u, p) by name.

    Raises ``ModelError`` naming the output for a function that fails, uses an undeclared
    name or symbol, returns something other than one value, or is not finite at q = qdot = 0,
    u = 0 and every parameter 1 (a NaN or an infinity written into it).
    """
    from hframe_id.models.user import DeclaredSymbols

    names = [c.name for c in system.coordinates]
    entries = []
    for output in declaration.outputs:
        if not isinstance(output, Output):
            entries.append(system.q[names.index(output)])
            continue
        where = f"{declaration.source}: model {declaration.name!r}: output {output.name!r}"
        symbols = (
            DeclaredSymbols("coordinate", {n: system.q[i] for i, n in enumerate(names)}, where),
            DeclaredSymbols("rate", {n: system.qdot[i] for i, n in enumerate(names)}, where),
            DeclaredSymbols(
                "input", {s.name: u[i] for i, s in enumerate(declaration.inputs)}, where
            ),
            DeclaredSymbols("parameter", dict(parameters), where),
        )
        try:
            value = output.function(*symbols)
        except ModelError:
            raise
        except Exception as err:
            raise ModelError(f"{where}: function failed: {type(err).__name__}: {err}") from None
        entries.append(_output_entry(value, where, system, parameters, u))
    return ca.vertcat(*entries)


def _output_entry(
    value: Any, where: str, system: LagrangianSystem, parameters: Mapping[str, ca.SX], u: ca.SX
) -> ca.SX:
    """One output's value as a scalar SX, checked (``output_expressions``)."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        value = ca.SX(float(value))
    if not isinstance(value, ca.SX):
        raise ModelError(
            f"{where}: function must return one expression or number, got {type(value).__name__}"
        )
    if value.numel() != 1:
        raise ModelError(
            f"{where}: function must return one value, got a {value.size1()}x{value.size2()} "
            "expression"
        )
    known = ca.vertcat(system.q, system.qdot, u, *parameters.values())
    allowed = {s.name() for s in ca.symvar(known)}
    unknown = sorted({s.name() for s in ca.symvar(value)} - allowed)
    if unknown:
        raise ModelError(f"{where}: uses undeclared symbol(s) {', '.join(unknown)}")
    probe = ca.Function("probe", [known], [value])
    point = [0.0] * (known.numel() - len(parameters)) + [1.0] * len(parameters)
    result = float(probe(point))
    if not math.isfinite(result):
        raise ModelError(
            f"{where}: is not finite ({result}) at q = qdot = 0, u = 0, parameters 1: a NaN or "
            "an infinity in its expression"
        )
    return value


def check_system(
    declaration: ModelDeclaration, system: LagrangianSystem, known: list[ca.SX]
) -> None:
    """Check a derived Lagrangian system against its declaration.

    ``known`` are the symbols the expressions may use (parameters and inputs; the coordinates
    and rates are the system's own). Raises ``ModelError`` for an expression that is missing
    or not symbolic, one using a symbol that was not declared, a friction on an unknown
    coordinate or with an undeclared parameter, and a coordinate without an equation of
    motion (no inertia in the kinetic energy: the mass matrix would be singular).
    """
    coordinates = [c.name for c in declaration.coordinates]
    for what, expression in (
        ("kinetic energy", system.kinetic_energy),
        ("potential energy", system.potential_energy),
        ("actuation", system.actuation),
    ):
        if not isinstance(expression, ca.SX):
            _fail(declaration, f"{what} is missing or not an expression ({expression!r})")
    allowed = {s.name() for s in ca.symvar(ca.vertcat(system.q, system.qdot, *known))}
    for what, expression in (
        ("kinetic energy", system.kinetic_energy),
        ("potential energy", system.potential_energy),
        ("actuation", system.actuation),
    ):
        unknown = sorted({s.name() for s in ca.symvar(expression)} - allowed)
        if unknown:
            _fail(declaration, f"{what} uses undeclared symbol(s) {', '.join(unknown)}")
    if system.actuation.numel() != len(coordinates):
        _fail(
            declaration,
            f"actuation has {system.actuation.numel()} entries for {len(coordinates)} coordinates",
        )
    names = declaration.parameter_names
    for friction in system.frictions:
        if friction.coordinate not in coordinates:
            _fail(declaration, f"friction on unknown coordinate {friction.coordinate!r}")
        for parameter in friction.parameters:
            if parameter not in names:
                _fail(
                    declaration,
                    f"friction on {friction.coordinate!r} uses undeclared parameter {parameter!r}",
                )
    mass, _ = ca.hessian(system.kinetic_energy, system.qdot)
    for j, name in enumerate(coordinates):
        if mass[j, j].is_zero():
            _fail(
                declaration,
                f"coordinate {name!r} has no equation of motion: the kinetic energy holds no "
                f"inertia for it (d^2 T / d{name}_dot^2 = 0)",
            )
