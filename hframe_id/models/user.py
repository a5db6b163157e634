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
import select
import signal
import sys
import threading
import traceback
import warnings
import weakref
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from types import ModuleType
from typing import Any, TypeVar

import casadi as ca

from hframe_id.documents import not_a_file
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
T = TypeVar("T")


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
    nests_in: str | None = None,
) -> ModelDeclaration:
    """Declare a model by its energies (see the module docstring).

    ``outputs`` are coordinate names or ``Output`` declarations (a speed, a current: any
    function of q, qdot, u, p). ``reference`` is the model's reference parameter file,
    relative to the file that calls ``declare``; ``fixed`` and ``held`` are held in fits by
    default (measured constants, and values the outputs do not determine); ``fit_defaults``
    (``shooting_interval``, ``continuity``) are how ``hframe-id fit`` transcribes the model's
    data by default. ``nests_in`` names a registered model with one parameter more that holds
    this one as a limit (as hframe-8-current-limit holds hframe-8): a fit tries it as well and
    keeps the one the data choose (``hframe_id.fitting.structure_choice``).
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
        nests_in=nests_in,
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


def _hanging(kind: str, path: Path, seconds: float) -> str:
    return (
        f"{kind} {path}: still running after {seconds:g} s (a loop or a wait at import?); "
        "HFRAME_ID_LOAD_TIMEOUT sets the limit"
    )


@contextmanager
def _signal_handling_kept() -> Iterator[None]:
    """The process's handlers of SIGINT, SIGTERM and SIGHUP and its signal wake-up, put back
    as they were once a file's code has run: a model file ignoring SIGINT and SIGTERM at
    import made the command impossible to interrupt but by SIGKILL. Only the main thread
    can set them (a Dask worker's thread leaves them alone)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    stopping = (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", None))
    handlers = {s: signal.getsignal(s) for s in stopping if s is not None}
    wakeup = signal.set_wakeup_fd(-1)
    signal.set_wakeup_fd(wakeup, warn_on_full_buffer=False)
    try:
        yield
    finally:
        for signum, handler in handlers.items():
            if handler is not None:  # None: set outside Python, cannot be put back
                signal.signal(signum, handler)
        signal.set_wakeup_fd(wakeup, warn_on_full_buffer=False)


@contextmanager
def guarded(
    path: Path, kind: str, error: type[ModelError] = ModelError, when: str = "while loaded"
) -> Iterator[None]:
    """Run a model or controller file's code (``kind``: ``"model file"``, ...; ``when`` it
    runs, for the message: loaded, or one of its functions called later) so that every
    way it can end and come back to Python is one ``error`` naming the file: an exception
    (with the file's line; any ``BaseException``, ``GeneratorExit`` too), ``sys.exit`` (any
    status, 0 too) or a ``KeyboardInterrupt`` it raises itself. The user's own Ctrl-C or
    SIGTERM (``Interrupted``) passes through, to end the command. The ways that do not come
    back (``os._exit``, a crash, a hang) are found before, by ``load_guarded``'s probe.
    The file cannot change how the command meets Ctrl-C (``_signal_handling_kept``)."""
    try:
        with _signal_handling_kept():
            yield
    except ModelError as err:
        message = str(err)
        raise error(message if str(path) in message else f"{path}: {message}") from None
    except SystemExit as err:
        raise error(f"{kind} {path}: calls sys.exit({shown(err.code)}) {when}") from None
    except Interrupted:
        raise
    except KeyboardInterrupt:
        raise error(f"{kind} {path}: raises KeyboardInterrupt {when}") from None
    except BaseException as err:  # GeneratorExit too: a BaseException of its own
        raise error(f"{kind} {path}: {error_line(err, path)}") from None


def _probe_usable() -> bool:
    """Whether ``_probe`` can run here: a POSIX ``fork``, from the main thread.

    Not from other threads (a Dask worker's): forking a process whose other threads may hold
    locks the child then needs can hang the child, which would read as the file hanging.
    The command line loads its files on the main thread; its other threads (the signal
    watchdog, progress timers) wait in calls that hold no lock the child takes.
    """
    return hasattr(os, "fork") and threading.current_thread() is threading.main_thread()


def _flush_standard_streams() -> None:
    """Write out what the process has buffered, so that the forked child holds none of it."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (AttributeError, OSError, ValueError):  # None, closed, or a broken pipe
            pass


def _probe_child(load: Callable[[], object], writer: int) -> None:
    """The forked child: run ``load`` with its output discarded, report on ``writer`` that
    it came back, however it ended, and end without running anything of the parent's
    (exit handlers, buffered output): ``os._exit``."""
    try:
        # a signal the child receives must not reach the parent's signal watchdog, which
        # would end the parent as interrupted (``hframe_id.cli.signals``)
        signal.set_wakeup_fd(-1)
        devnull = os.open(os.devnull, os.O_RDWR)
        for descriptor in (0, 1, 2):  # the parent's input is not the file's to read
            os.dup2(devnull, descriptor)
        sys.stdout = sys.stderr = open(devnull, "w", closefd=False)  # noqa: SIM115
        try:
            load()
        except BaseException:  # the parent runs it again and reports what it raises
            pass
        os.write(writer, b"ok")
    finally:
        os._exit(0)


def _probe(kind: str, path: Path, seconds: float, load: Callable[[], object]) -> str | None:
    """Run ``load`` in a forked child first: the error line for what the file's code does
    there that a process cannot survive or catch (``None``: it came back, with a result or
    an exception, within ``seconds``; 0: no limit).

    ``os._exit`` and a crash end the process at once and a hang defeats any handler, so
    only another process can see them. A fork is a copy of this one (CasADi and the models
    already imported): measured for ``models/emps_axis.py``, whose load takes 2 ms, the
    probe adds 9-16 ms (the fork and the child's exit), within the noise of the command's
    start-up (270 ms). The child's output is discarded: the file runs again in this process
    afterwards, and prints there.
    """
    reader, writer = os.pipe()
    _flush_standard_streams()
    try:
        with warnings.catch_warnings():
            # Python 3.12+ warns of forking a process with threads; the child runs only the
            # file's code (``_probe_usable``)
            warnings.simplefilter("ignore", DeprecationWarning)
            pid = os.fork()
    except OSError:  # no process to spare (EAGAIN, ENOMEM): the load runs here only
        os.close(reader)
        os.close(writer)
        return None
    if pid == 0:
        os.close(reader)
        _probe_child(load, writer)
    os.close(writer)
    reaped = False
    try:
        poller = select.poll()
        poller.register(reader, select.POLLIN)
        if not poller.poll(seconds * 1000 if seconds > 0 else None):
            return _hanging(kind, path, seconds)
        came_back = os.read(reader, 2) == b"ok"
        _, status = os.waitpid(pid, 0)
        reaped = True
    finally:
        os.close(reader)
        if not reaped:  # a hang, or this process interrupted while it waited
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
    if came_back:
        return None
    if os.WIFSIGNALED(status):
        ending = f"kills the process ({signal.Signals(os.WTERMSIG(status)).name})"
    else:
        ending = f"ends the process at once (os._exit({os.waitstatus_to_exitcode(status)}))"
    return f"{kind} {path}: {ending} while loaded"


#: Threads that model and controller files started while they were loaded and left
#: running, by the file ("model file /path/m.py"): a fact about the process, which the
#: command line reads when it ends (``threads_left_running``).
_LEFT_RUNNING: weakref.WeakKeyDictionary[threading.Thread, str] = weakref.WeakKeyDictionary()


def threads_left_running() -> list[tuple[str, threading.Thread]]:
    """The threads a loaded file started that still run and would keep the process alive
    at exit (not daemons), with the file that started each ("model file /path/m.py")."""
    return [
        (file, thread)
        for thread, file in list(_LEFT_RUNNING.items())
        if thread.is_alive() and not thread.daemon
    ]


def _checked_source(path: str | Path, kind: str, error: type[ModelError]) -> Path:
    path = Path(path).resolve()
    if not path.is_file():  # a folder or a pipe "did not exist"
        raise error(f"{kind} {path}: {not_a_file(path)}")
    if path.suffix != ".py":
        raise error(f"{kind} {path}: expected a Python file (.py), got {path.suffix!r}")
    return path


def load_guarded(
    path: str | Path, kind: str, error: type[ModelError], load: Callable[[Path], T]
) -> T:
    """``load(path)`` (import a model or controller file, check what it declares) so that
    however the file's code ends it is one ``error`` line naming the file.

    First in a forked child (``_probe``; on POSIX, from the main thread): a file that ends
    the process there (``os._exit``, a crash) or still runs after ``load_timeout_s()`` is
    refused before it runs here. Then here, under ``guarded`` for the endings a process can
    catch. Elsewhere (another thread, Windows) only the second step runs, without a time
    limit. Threads the file starts and leaves running are noted (``threads_left_running``).
    """
    path = _checked_source(path, kind, error)
    seconds = load_timeout_s()
    if _probe_usable():
        problem = _probe(kind, path, seconds, lambda: load(path))
        if problem:
            raise error(problem)
    before = set(threading.enumerate())
    try:
        return load(path)
    finally:
        for thread in threading.enumerate():
            if thread not in before and not thread.daemon:
                _LEFT_RUNNING[thread] = f"{kind} {path}"


def run_declaration_file(
    path: str | Path, kind: str, error: type[ModelError] = ModelError
) -> tuple[Path, ModuleType]:
    """Execute a model or controller file (``kind``: ``"model file"``, ``"controller file"``)
    as a module of its own; returns its resolved path and the module.

    Every problem (no such file, not Python, any way its code can end that comes back to
    Python: ``guarded``) is one ``error`` line naming the file, and the line of the file for
    a Python error. Loaders call it inside ``load_guarded``, which also catches the ways
    that do not come back.
    """
    path = _checked_source(path, kind, error)
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

    Every problem, however the file's code ends (``load_guarded``), is a one-line
    ``ModelError`` naming the file and the item.
    """
    return load_guarded(path, "model file", ModelError, _load_model_file)


def _load_model_file(path: Path) -> ModelDeclaration:
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
