"""What a controller is, declared once: the discrete law a closed-loop simulation runs.

The controller's counterpart of a model declaration (``hframe_id.models.declaration``): named
signals with units, gains with values and units, and a law written with CasADi symbols. The
built-ins are the thesis's reset-windup PID (``hframe_id.control.pid.pid_controller``) and the
EMPS position loop (``models/emps_controller.py``); any other is a Python file that sets
``CONTROLLER = declare_controller(...)`` (``hframe_id.control.controller_file``,
docs/custom-models.md).

One sample k, at t_k = k T with T the controller's sample period, as the Simulink diagrams of
the thesis (Fig. 5.8) and of the EMPS benchmark (Simulink_EMPS_Rigide.slx) run it:

1. the plant's measured outputs y_k = y(t_k) and the references r_k = r(t_k) are read;
2. the law computes the commands and the next memory, (c_k, z_{k+1}) = law(y_k, r_k, z_k,
   gains, T), from z_0 = 0;
3. the plant gets c_{k-d} over [t_k, t_{k+1}) (d = ``delay_samples``, 0 before k = d), clipped
   to its ``limits``, plus the recording's disturbance signal at t_k where one is declared
   (added after the saturation, where the EMPS benchmark adds its force pulses);
4. the plant integrates over the sample with that input held (zero-order hold).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import casadi as ca
import numpy as np

from hframe_id.errors import ControllerError, ModelError
from hframe_id.models.declaration import check_name
from hframe_id.models.spec import Signal
from hframe_id.models.user import DeclaredSymbols, error_line, guarded

if TYPE_CHECKING:
    from hframe_id.recordings.recording import Recording

#: law(y, r, z, g, T) -> {"commands": {name: expression}, "states": {name: expression}}.
Law = Callable[..., Mapping[str, Any]]
#: The sample period [s]: a number, a function of the recording, or None (the recording's).
SamplePeriod = float | Callable[["Recording"], float] | None
#: Most samples a command may be delayed by (a computation or transport delay).
MAX_DELAY_SAMPLES = 100
#: What a law returns: the commands, and the next memory when it has any.
LAW_KEYS = ("commands", "states")
#: The sample period the law is traced with when a declaration is checked [s].
CHECK_PERIOD_S = 1e-3
_SYMBOL = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


@dataclass(frozen=True)
class Gain:
    """A controller constant: name, value, unit, e.g. ``Gain("kp", 160.18, "1/s", "...")``."""

    name: str
    value: float
    unit: str
    description: str = ""


@dataclass(frozen=True)
class ControllerDeclaration:
    """A discrete controller, declared once (see the module docstring for its timing).

    Attributes
    ----------
    name : controller name, e.g. ``"emps-position-loop"``.
    description : one line, with the source of the controller.
    commands : the model inputs it computes (``Signal``), e.g. ``vir`` [V].
    measured : the model outputs it reads at every sample, e.g. ``("qm",)``.
    references : the recording's signals it reads at every sample (``Signal``), e.g. ``qg`` [m].
    states : its memory (``Signal``), zero at the first sample.
    gains : its constants (``Gain``), passed to the law by name.
    law : ``law(y, r, z, g, T)``: mappings of CasADi symbols by declared name (outputs,
        references, states, gains) and the sample period T [s]; returns ``{"commands": {...},
        "states": {...}}`` with an expression for every declared command and state.
    sample_period_s : T [s]; a function of the recording, or None for the recording's own.
    delay_samples : d, samples between computing a command and applying it.
    limits : (command, lower, upper) saturations applied after the delay.
    disturbances : (command, signal): a recording signal added to the command after the
        saturation, when the recording holds it (a run without it adds nothing).
    source : where the declaration lives (module or file), for error messages.
    controller_file : the file it was loaded from (``--controller``), else None.
    """

    name: str
    description: str
    commands: tuple[Signal, ...]
    measured: tuple[str, ...]
    references: tuple[Signal, ...]
    states: tuple[Signal, ...]
    gains: tuple[Gain, ...]
    law: Law
    sample_period_s: SamplePeriod = None
    delay_samples: int = 0
    limits: tuple[tuple[str, float, float], ...] = ()
    disturbances: tuple[tuple[str, str], ...] = ()
    source: str = "hframe_id"
    controller_file: Path | None = None

    def __post_init__(self) -> None:
        check_declaration(self)

    @property
    def where(self) -> str:
        """How error messages name the controller: its source and name."""
        return f"{self.source}: controller {self.name!r}"

    @property
    def command_names(self) -> tuple[str, ...]:
        """Names of the commands, in declaration order."""
        return tuple(c.name for c in self.commands)

    def gain_vector(self) -> np.ndarray:
        """The gains' values in declaration order (the law function's ``g`` input)."""
        return np.array([g.value for g in self.gains], dtype=float)

    def limit(self, command: str) -> tuple[float, float]:
        """(lower, upper) limits of a command; +/-inf where none is declared."""
        for name, lower, upper in self.limits:
            if name == command:
                return lower, upper
        return -math.inf, math.inf

    def sample_period(self, recording: Recording) -> float:
        """T [s] for a run against ``recording``. Raises ``ControllerError`` for a function
        that gives no positive number."""
        period = self.sample_period_s
        if period is None:
            return float(recording.sample_period_s)
        if callable(period) and self.controller_file is not None:
            # the file's code, run again for each recording: however it ends, one line
            when = "in its sample period function"
            with guarded(self.controller_file, "controller file", ControllerError, when):
                value = period(recording)
        else:
            value = period(recording) if callable(period) else period
        if not _positive(value):
            raise ControllerError(f"{self.where}: sample period must be > 0 s, got {value!r}")
        return float(value)


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _positive(value: Any) -> bool:
    return _finite(value) and value > 0


def _fail(declaration: ControllerDeclaration, message: str) -> None:
    raise ControllerError(f"{declaration.where}: {message}")


def _check_names(declaration: ControllerDeclaration) -> None:
    named = [
        ("command", declaration.commands, Signal),
        ("reference", declaration.references, Signal),
        ("state", declaration.states, Signal),
        ("gain", declaration.gains, Gain),
    ]
    for what, items, kind in named:
        seen: set[str] = set()
        for item in items:
            if not isinstance(item, kind):
                _fail(declaration, f"{what} {item!r} must be a {kind.__name__}")
            if not isinstance(item.name, str) or not _SYMBOL.match(item.name):
                _fail(declaration, f"{what} name {item.name!r} is not an identifier")
            if not isinstance(item.unit, str) or not item.unit.strip():
                _fail(declaration, f"{what} {item.name!r} has no unit (use '-' if dimensionless)")
            if item.name in seen:
                _fail(declaration, f"{what} {item.name!r} is declared twice")
            seen.add(item.name)
    for name in declaration.measured:
        if not isinstance(name, str) or not _SYMBOL.match(name):
            _fail(declaration, f"measured output {name!r} is not an identifier")
    for gain in declaration.gains:
        if not _finite(gain.value):
            _fail(declaration, f"gain {gain.name!r} must be a finite number, got {gain.value!r}")


def check_declaration(declaration: ControllerDeclaration) -> None:
    """Check what needs no tracing of the law: names, units, values, timing, where the limits
    and disturbances act. Raises ``ControllerError`` naming the source and the item."""
    check_name(declaration.name, f"{declaration.source}: controller name", ControllerError)
    if not declaration.commands:
        _fail(declaration, "declares no commands (the model inputs it computes)")
    _check_names(declaration)
    if not callable(declaration.law):
        _fail(declaration, f"law must be a function law(y, r, z, g, T), got {declaration.law!r}")
    period = declaration.sample_period_s
    if period is not None and not callable(period) and not _positive(period):
        _fail(
            declaration, f"sample_period_s must be > 0 s (or None: the recording's), got {period!r}"
        )
    delay = declaration.delay_samples
    if isinstance(delay, bool) or not isinstance(delay, int) or not 0 <= delay <= MAX_DELAY_SAMPLES:
        _fail(
            declaration,
            f"delay_samples must be an integer in 0..{MAX_DELAY_SAMPLES}, got {delay!r}",
        )
    commands = declaration.command_names
    for name, lower, upper in declaration.limits:
        if name not in commands:
            _fail(
                declaration, f"limits on {name!r}, which is not a command ({', '.join(commands)})"
            )
        if not (_finite(lower) and _finite(upper) and lower < upper):
            _fail(
                declaration,
                f"limits of {name!r} must be finite with lower < upper, got ({lower}, {upper})",
            )
    for name, signal in declaration.disturbances:
        if name not in commands:
            _fail(
                declaration,
                f"disturbance on {name!r}, which is not a command ({', '.join(commands)})",
            )
        if not isinstance(signal, str) or not _SYMBOL.match(signal):
            _fail(declaration, f"disturbance signal {signal!r} is not an identifier")


def _expressions(
    declaration: ControllerDeclaration, result: Any, key: str, declared: tuple[str, ...]
) -> list[ca.SX]:
    """The law's expressions for ``key`` (commands or states), in declaration order."""
    given = result.get(key) or {}
    if not isinstance(given, Mapping):
        _fail(declaration, f"law returns {key} as {type(given).__name__}, not a dict by name")
    unknown = [name for name in given if name not in declared]
    if unknown:
        _fail(
            declaration,
            f"law returns undeclared {key[:-1]}(s) {', '.join(map(repr, unknown))}; "
            f"declared: {', '.join(declared) or 'none'}",
        )
    expressions = []
    for name in declared:
        if name not in given:
            what = "command" if key == "commands" else "state (its next value)"
            _fail(declaration, f"law returns no {what} {name!r}")
        value = given[name]
        if isinstance(value, int | float) and not isinstance(value, bool):
            value = ca.SX(float(value))
        if not isinstance(value, ca.SX) or value.numel() != 1:
            _fail(
                declaration, f"law's {key[:-1]} {name!r} must be a scalar expression, got {value!r}"
            )
        expressions.append(value)
    return expressions


@lru_cache(maxsize=32)
def traced_law(
    declaration: ControllerDeclaration, sample_period_s: float, when: str = "while loaded"
) -> ca.Function:
    """``law_function``; for a controller file, its law run under ``guarded`` (``when``, for
    the message): however the file's code ends, one ``ControllerError`` naming the file. The
    loader traces the law at ``CHECK_PERIOD_S``, a closed loop again at its own period, where
    a law's ``sys.exit`` ended the command with its status and no word."""
    path = declaration.controller_file
    if path is None:  # declared in Python: its errors are the caller's
        return law_function(declaration, sample_period_s)
    with guarded(path, "controller file", ControllerError, when):
        try:
            return law_function(declaration, sample_period_s)
        except (ControllerError, KeyboardInterrupt, SystemExit):
            raise
        except Exception as err:
            raise ControllerError(f"controller file {path}: law: {error_line(err, path)}") from None


def law_function(declaration: ControllerDeclaration, sample_period_s: float) -> ca.Function:
    """The law as a CasADi function (y, r, z, g) -> (c, z_next) at sample period T [s].

    y in the order of ``measured``, r of ``references``, z of ``states``, g of ``gains``, c of
    ``commands``. Raises ``ControllerError`` for a law that returns something other than an
    expression for every declared command and state, or uses an undeclared name or symbol.
    """
    where = f"controller {declaration.name!r}"
    vectors = {
        "y": ca.SX.sym("y", len(declaration.measured)),
        "r": ca.SX.sym("r", len(declaration.references)),
        "z": ca.SX.sym("z", len(declaration.states)),
        "g": ca.SX.sym("g", len(declaration.gains)),
    }
    names = {
        "y": ("measured output", declaration.measured),
        "r": ("reference", [s.name for s in declaration.references]),
        "z": ("state", [s.name for s in declaration.states]),
        "g": ("gain", [g.name for g in declaration.gains]),
    }
    arguments = [
        DeclaredSymbols(what, {n: vectors[key][i] for i, n in enumerate(listed)}, where)
        for key, (what, listed) in names.items()
    ]
    try:
        result = declaration.law(*arguments, sample_period_s)
    except ModelError as err:
        raise ControllerError(f"{declaration.source}: {err}") from None
    if not isinstance(result, Mapping):
        _fail(declaration, f"law must return a dict, got {type(result).__name__}")
    unknown = [k for k in result if k not in LAW_KEYS]
    if unknown:
        _fail(
            declaration,
            f"law returns unknown key(s) {', '.join(map(repr, unknown))}; "
            f"valid: {', '.join(LAW_KEYS)}",
        )
    commands = _expressions(declaration, result, "commands", declaration.command_names)
    states = _expressions(declaration, result, "states", tuple(s.name for s in declaration.states))
    outputs = [ca.vertcat(*commands), ca.vertcat(*states) if states else ca.SX(0, 1)]
    known = {s.name() for s in ca.symvar(ca.vertcat(*vectors.values()))}
    used = {s.name() for expression in outputs for s in ca.symvar(expression)}
    if used - known:
        _fail(declaration, f"law uses undeclared symbol(s) {', '.join(sorted(used - known))}")
    return ca.Function(
        "controller_law", list(vectors.values()), outputs, list(vectors), ["c", "z_next"]
    )
