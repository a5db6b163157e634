"""Models declared by their energies, without touching the package (docs/custom-models.md).

A model file is a Python file that sets ``MODEL = declare(...)``::

    def equations(q, qdot, u, p):
        return {
            "kinetic": 0.5 * p["M"] * qdot["q"] ** 2,
            "potential": 0,
            "forces": {"q": p["k_f"] * u["v"]},
            "friction": {"q": ("F_v", "F_c")},
        }

``q``, ``qdot``, ``u`` and ``p`` map the declared names to CasADi symbols; a name that was not
declared is an error naming the file and the name. Lagrange's equations are then derived the
same way as for the thesis's variants (``hframe_id.models.lagrange``).
"""

from __future__ import annotations

import importlib.util
import math
import os
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from types import ModuleType
from typing import Any

import casadi as ca

from hframe_id.errors import Interrupted, ModelError, shown
from hframe_id.models.declaration import ModelDeclaration, Output
from hframe_id.models.lagrange import Friction, LagrangianSystem
from hframe_id.models.options import ModelOptions
from hframe_id.models.spec import ParameterSpec, Signal

#: What ``equations`` must return: the two energies, and optionally the generalized forces
#: other than friction (inputs, offsets) and the friction-bearing coordinates.
REQUIRED_KEYS = ("kinetic", "potential")
OPTIONAL_KEYS = ("forces", "friction")

Equations = Callable[..., Mapping[str, Any]]


class DeclaredSymbols(Mapping[str, ca.SX]):
    """Symbols by declared name; looking up an undeclared name is a ``ModelError``."""

    def __init__(self, what: str, symbols: dict[str, ca.SX], where: str) -> None:
        self._what, self._symbols, self._where = what, symbols, where

    def __getitem__(self, name: str) -> ca.SX:
        if name not in self._symbols:
            raise ModelError(
                f"{self._where}: uses undeclared {self._what} {name!r}; declared: "
                f"{', '.join(self._symbols) or 'none'}"
            )
        return self._symbols[name]

    def __iter__(self):
        return iter(self._symbols)

    def __len__(self) -> int:
        return len(self._symbols)


def _expression(value: Any, what: str, where: str) -> ca.SX:
    if isinstance(value, ca.SX):
        return value
    if isinstance(value, int | float) and not isinstance(value, bool):
        return ca.SX(float(value))
    raise ModelError(f"{where}: {what} must be an expression or a number, got {value!r}")


def _lagrangian(
    where: str,
    coordinates: tuple[Signal, ...],
    inputs: tuple[Signal, ...],
    equations: Equations,
) -> Callable[[dict[str, ca.SX], ca.SX, ModelOptions], LagrangianSystem]:
    """A Lagrangian builder from a user's ``equations(q, qdot, u, p)``."""
    names = [c.name for c in coordinates]

    def build(p: dict[str, ca.SX], u: ca.SX, options: ModelOptions) -> LagrangianSystem:
        q = ca.SX.sym("q", len(names))
        qdot = ca.SX.sym("qdot", len(names))
        result = equations(
            DeclaredSymbols("coordinate", {n: q[i] for i, n in enumerate(names)}, where),
            DeclaredSymbols("rate", {n: qdot[i] for i, n in enumerate(names)}, where),
            DeclaredSymbols("input", {s.name: u[i] for i, s in enumerate(inputs)}, where),
            DeclaredSymbols("parameter", dict(p), where),
        )
        if not isinstance(result, Mapping):
            raise ModelError(f"{where}: equations must return a dict, got {type(result).__name__}")
        for key in REQUIRED_KEYS:
            if key not in result:
                raise ModelError(
                    f"{where}: equations return no {key!r} energy (write {key}=0 if it is zero)"
                )
        unknown = [k for k in result if k not in REQUIRED_KEYS + OPTIONAL_KEYS]
        if unknown:
            raise ModelError(
                f"{where}: equations return unknown key(s) {', '.join(map(repr, unknown))}; "
                f"valid: {', '.join(REQUIRED_KEYS + OPTIONAL_KEYS)}"
            )
        forces = [ca.SX(0)] * len(names)
        for name, force in dict(result.get("forces") or {}).items():
            if name not in names:
                raise ModelError(f"{where}: force on undeclared coordinate {name!r}")
            forces[names.index(name)] = _expression(force, f"force on {name!r}", where)
        frictions = []
        for name, names_ in dict(result.get("friction") or {}).items():
            if not (isinstance(names_, Sequence) and len(names_) in (2, 4)):
                raise ModelError(
                    f"{where}: friction on {name!r} must be (viscous, coulomb) or (viscous, "
                    f"coulomb, static, stribeck velocity) parameter names, got {names_!r}"
                )
            frictions.append(Friction(name, *map(str, names_)))
        return LagrangianSystem(
            coordinates,
            q,
            qdot,
            _expression(result["kinetic"], "kinetic energy", where),
            _expression(result["potential"], "potential energy", where),
            ca.vertcat(*forces),
            tuple(frictions),
        )

    return build


def _caller_file() -> Path | None:
    """The file of the code that called ``declare`` (its model file or plug-in module)."""
    file = sys._getframe(2).f_globals.get("__file__")
    return Path(file).resolve() if file else None


def declare(
    name: str,
    description: str,
    coordinates: Sequence[Signal],
    inputs: Sequence[Signal],
    outputs: Sequence[str | Output],
    parameters: Sequence[ParameterSpec],
    equations: Equations,
    reference: str | Path | None = None,
    reference_label: str = "",
    fixed: Sequence[str] = (),
    held: Sequence[str] = (),
    fit_defaults: Mapping[str, Any] | None = None,
) -> ModelDeclaration:
    """Declare a model by its energies (see the module docstring).

    ``outputs`` are coordinate names or ``Output`` declarations (a speed, a current: any
    function of q, qdot, u, p). ``reference`` is the model's reference parameter file,
    relative to the file that calls ``declare``; ``fixed`` and ``held`` are held in fits by
    default (measured constants, and values the outputs do not determine); ``fit_defaults``
    (``shooting_interval``, ``continuity``) are how ``hframe-id fit`` transcribes the model's
    data by default.
    """
    caller = _caller_file()
    if reference is not None and not Path(reference).is_absolute():
        reference = (caller.parent if caller else Path.cwd()) / reference
    coordinates, inputs = tuple(coordinates), tuple(inputs)
    return ModelDeclaration(
        name=name,
        description=description,
        parameters=tuple(parameters),
        coordinates=coordinates,
        inputs=inputs,
        outputs=tuple(outputs),
        lagrangian=_lagrangian(f"model {name!r}", coordinates, inputs, equations),
        reference_file=Path(reference) if reference is not None else None,
        reference_label=reference_label,
        fixed=tuple(fixed),
        held=tuple(held),
        fit_defaults=tuple(dict(fit_defaults or {}).items()),
        source=str(caller) if caller else "<declare>",
    )


def error_line(err: BaseException, path: Path) -> str:
    """The error with the line of the declaration file it happened on."""
    frames = [f for f in traceback.extract_tb(err.__traceback__) if Path(f.filename) == path]
    line = f" (line {frames[-1].lineno})" if frames else ""
    if isinstance(err, SyntaxError):
        line = f" (line {err.lineno})"
    return f"{type(err).__name__}{line}: {err}".splitlines()[0]


#: Seconds a model or controller file may run while it is loaded (its import, and deriving
#: its equations or tracing its law) before it counts as hanging; ``$HFRAME_ID_LOAD_TIMEOUT``
#: overrides it (0: no limit).
LOAD_TIMEOUT_S = 30.0


class _LoadTimeout(BaseException):
    """Raised into a file's code by the load timer (a BaseException, so that a file's
    ``except Exception`` cannot swallow it)."""


def load_timeout_s() -> float:
    """The load timeout [s]: ``$HFRAME_ID_LOAD_TIMEOUT`` if set, else ``LOAD_TIMEOUT_S``.

    Read at each load, like the native-code settings (``hframe_id.native.settings``): model
    files are loaded by the command line, the Python API and Dask workers alike.
    """
    text = os.environ.get("HFRAME_ID_LOAD_TIMEOUT")
    if text is None:
        return LOAD_TIMEOUT_S
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        raise ModelError(
            f"HFRAME_ID_LOAD_TIMEOUT must be a number of seconds >= 0, got {shown(text)}"
        )
    return value


def _timer_usable() -> bool:
    """Whether ``_timer`` can interrupt this thread (the main thread, where signals come)."""
    return hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()


@contextmanager
def _timer(seconds: float) -> Iterator[None]:
    """Raise ``_LoadTimeout`` in the block after ``seconds`` (0: never).

    A real-time interval timer (``setitimer``) whose SIGALRM handler raises: Python runs the
    handler between two bytecodes of the file's code, and a blocking call (``time.sleep``,
    a socket read) is interrupted and not resumed (PEP 475: the handler's exception ends
    it). Only the main thread receives signals, so elsewhere (a Dask worker's thread) and
    on Windows the block runs without a limit; C code that never returns to Python (a
    CasADi call that does not end) is not interrupted either. The previous handler and
    timer are put back afterwards.
    """
    if not (seconds > 0 and _timer_usable()):
        yield
        return

    def expire(signum: int, frame: object) -> None:
        raise _LoadTimeout

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


#: Seconds a file may run beyond the load timeout when it defeats the timer (catches its
#: exception in a loop, ignores SIGALRM or stops the timer) before the process is ended.
LOAD_GRACE_S = 2.0


@contextmanager
def _last_resort(seconds: float, line: str) -> Iterator[None]:
    """End the process with the error ``line`` and exit status 2 if the block still runs
    after ``seconds`` (0: never): for a file that defeats ``_timer``, which nothing else can
    stop. A daemon thread, cancelled when the block ends; the command line's outputs are
    written after the files are loaded, so none is left half-made. Where ``_timer`` does
    not run (a Dask worker's thread) neither does this: the load has no limit there."""
    if not (seconds > 0 and _timer_usable()):
        yield
        return

    def expire() -> None:
        print(f"hframe-id: error: {line}", file=sys.__stderr__, flush=True)
        os._exit(2)

    watchdog = threading.Timer(seconds, expire)
    watchdog.daemon = True
    watchdog.start()
    try:
        yield
    finally:
        watchdog.cancel()


def _hanging(kind: str, path: Path, seconds: float) -> str:
    return (
        f"{kind} {path}: still running after {seconds:g} s (a loop or a wait at import?); "
        "HFRAME_ID_LOAD_TIMEOUT sets the limit"
    )


@contextmanager
def guarded(path: Path, kind: str, error: type[ModelError] = ModelError) -> Iterator[None]:
    """Run a model or controller file's code (``kind``: ``"model file"``, ...) so that every
    way it can end is one ``error`` naming the file: an exception (with the file's line; any
    ``BaseException``, ``GeneratorExit`` too), ``sys.exit`` (any status, 0 too), a
    ``KeyboardInterrupt`` it raises itself, or running longer than ``load_timeout_s()``. A
    file that defeats the timer ends the process ``LOAD_GRACE_S`` later with the same line
    (``_last_resort``). The user's own Ctrl-C or SIGTERM (``Interrupted``) passes through,
    to end the command. Only ``os._exit`` in the file escapes: it ends the process at once."""
    seconds = load_timeout_s()
    try:
        with _last_resort(seconds and seconds + LOAD_GRACE_S, _hanging(kind, path, seconds)):
            with _timer(seconds):
                yield
    except ModelError as err:
        message = str(err)
        raise error(message if str(path) in message else f"{path}: {message}") from None
    except _LoadTimeout:
        raise error(_hanging(kind, path, seconds)) from None
    except SystemExit as err:
        raise error(f"{kind} {path}: calls sys.exit({shown(err.code)}) while loaded") from None
    except Interrupted:
        raise
    except KeyboardInterrupt:
        raise error(f"{kind} {path}: raises KeyboardInterrupt while loaded") from None
    except BaseException as err:  # GeneratorExit too: a BaseException of its own
        raise error(f"{kind} {path}: {error_line(err, path)}") from None


def run_declaration_file(
    path: str | Path, kind: str, error: type[ModelError] = ModelError
) -> tuple[Path, ModuleType]:
    """Execute a model or controller file (``kind``: ``"model file"``, ``"controller file"``)
    as a module of its own; returns its resolved path and the module.

    Every problem (no such file, not Python, any way its code can end: ``guarded``) is one
    ``error`` line naming the file, and the line of the file for a Python error.
    """
    path = Path(path).resolve()
    if not path.is_file():
        raise error(f"{kind} {path} does not exist")
    if path.suffix != ".py":
        raise error(f"{kind} {path}: expected a Python file (.py), got {path.suffix!r}")
    module_name = f"hframe_id_{kind.replace(' ', '_')}_{abs(hash(str(path)))}"
    spec = importlib.util.spec_from_file_location(module_name, path)
    module = importlib.util.module_from_spec(spec)
    with guarded(path, kind, error):
        spec.loader.exec_module(module)
    return path, module


def sibling_module(model_file: str | Path, file_name: str) -> ModuleType:
    """The model file ``file_name`` next to ``model_file`` (a model file's ``__file__``), as a
    module: one model file building on another's equations (``models/hframe8_stribeck.py``).
    The loader puts no folder on ``sys.path``, so a plain import would not find it."""
    path = Path(model_file).with_name(file_name)
    spec = importlib.util.spec_from_file_location(f"hframe_id_model_sibling_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def load_model_file(path: str | Path) -> ModelDeclaration:
    """Load a model file, check it by deriving its equations, and register its declaration.

    Every problem is a one-line ``ModelError`` naming the file and the item.
    """
    from hframe_id.models.model import freeze
    from hframe_id.models.registry import register

    path, module = run_declaration_file(path, "model file")
    declared = getattr(module, "MODEL", None)
    if not isinstance(declared, ModelDeclaration):
        raise ModelError(
            f"model file {path}: defines no MODEL = declare(...) (found {type(declared).__name__})"
        )
    declared = replace(declared, source=str(path), model_file=path)
    with guarded(path, "model file"):
        try:
            freeze(declared, ModelOptions())
        except (ModelError, KeyboardInterrupt, SystemExit):
            raise
        except Exception as err:
            raise ModelError(f"model file {path}: deriving the equations failed: {err}") from None
    return register(declared)
