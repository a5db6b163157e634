"""The ``hframe-id`` command line: one entry point, one module per subcommand.

Each command module defines ``register(subparsers)``, which adds its parser and sets
``handler`` to a function ``(args) -> int``. Errors derived from ``HframeIdError`` are printed
as one line (``hframe-id: error: ...``) with exit status 2; nothing is printed from deep inside
a library, and warnings reach the user as one line (``hframe-id: warning: ...``) without the
source location Python adds. Ctrl-C and SIGTERM end any command with one line and exit
status 130, leaving no half-written output (``signals``).

Only the module of the command being run is imported (``hframe-id --help`` imports none):
every other command gets a placeholder parser that shows its line in the listing. Command
modules keep CasADi, NumPy, pandas and matplotlib out of their module level for the same
reason, so that ``hframe-id COMMAND --help`` answers at once.
"""

from __future__ import annotations

import argparse
import atexit
import errno
import importlib
import io
import os
import sys
import threading
import warnings
from collections.abc import Sequence

from hframe_id.cli import model_files, outputs, progress, signals
from hframe_id.errors import HframeIdError, bounded_message, shown

#: The subcommands in the order ``hframe-id --help`` lists them: (name, module, one line of
#: help). To add a command, write a module with ``register(subparsers)`` and add its line.
COMMANDS: tuple[tuple[str, str, str], ...] = (
    (
        "models",
        "hframe_id.cli.models_command",
        "list model variants and their signals and parameters",
    ),
    ("params", "hframe_id.cli.params_command", "show or check parameter files"),
    (
        "linearize",
        "hframe_id.cli.linearize_command",
        "poles and zeros of the model linearized about rest",
    ),
    (
        "export",
        "hframe_id.cli.export_command",
        "export parameters or the linear state-space model (JSON, CSV, MATLAB, ...)",
    ),
    (
        "reduce",
        "hframe_id.cli.reduce_command",
        "reduce an hframe-20 parameter file to an hframe-8 one (section 4.1)",
    ),
    ("record", "hframe_id.cli.record_command", "run an experiment on a rig and record it (MCAP)"),
    (
        "inspect",
        "hframe_id.cli.inspect_command",
        "show what a recording holds and how good its data is",
    ),
    (
        "import",
        "hframe_id.cli.import_command",
        "convert a CSV or MATLAB .mat log into the log format (any rig)",
    ),
    ("datasets", "hframe_id.cli.datasets_command", "make, list or verify the shipped datasets"),
    (
        "simulate",
        "hframe_id.cli.simulate_command",
        "open-loop simulation (steps, pulses, CSV or recorded voltages) to CSV / MCAP",
    ),
    (
        "control",
        "hframe_id.cli.control_command",
        "closed-loop PID simulation on the test square or point-to-point moves",
    ),
    (
        "reproduce",
        "hframe_id.cli.reproduce_command",
        "reproduce the Chapter 5 controller tables (markdown report with plots)",
    ),
    (
        "fit",
        "hframe_id.cli.fit_command",
        "fit stiffness, friction and inertia to recordings (multiple shooting)",
    ),
    (
        "validate",
        "hframe_id.cli.validate_command",
        "simulation / k-step fit [%%] and residual tests of parameter files on recordings",
    ),
    ("design", "hframe_id.cli.design_command", "design an experiment within the rig's limits"),
    ("batch", "hframe_id.cli.batch_command", "fit every entry of a manifest on Dask into Parquet"),
    ("fleet", "hframe_id.cli.fleet_command", "synthetic fleets; rig histories and drift flags"),
    ("cache", "hframe_id.cli.cache_command", "show or clear the cache of compiled native code"),
)


def chosen_command(argv: Sequence[str]) -> str | None:
    """The subcommand named on the command line: its first word that is not an option (the
    top-level options, ``--help`` and ``--version``, take no value)."""
    return next((word for word in argv if not word.startswith("-")), None)


class _VersionAction(argparse.Action):
    """``--version``: the installed version, read only when asked for (the package metadata
    cost 30-64 ms to import, measured, up to half of ``hframe-id --help``)."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, **kwargs):
        super().__init__(
            option_strings, dest, nargs=0, default=argparse.SUPPRESS, help="show the version"
        )

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        from hframe_id import __version__

        parser.exit(message=f"hframe-id {__version__}\n")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser with ``command`` registered in full (its module imported) and the other
    commands as placeholders; ``command=None``: placeholders only."""
    parser = argparse.ArgumentParser(
        prog="hframe-id",
        description="Identify, simulate and control belt-driven H-frame XY stages.",
    )
    parser.add_argument("--version", action=_VersionAction)
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, module, help_line in COMMANDS:
        if name == command:
            importlib.import_module(module).register(subparsers)
        else:
            subparsers.add_parser(name, help=help_line, add_help=False)
    if command in model_files.COMMANDS:
        model_files.add_option(subparsers.choices[command])
    return parser


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` for the command line: one line, without source location."""
    print(f"hframe-id: warning: {bounded_message(message)}", file=file or sys.stderr)


def _detach_stdout() -> None:
    """Point standard output at /dev/null, so that Python's own flush at exit does not fail
    again on what could not be written."""
    try:
        descriptor = sys.stdout.fileno()
    except (OSError, ValueError):  # not a file (the tests' capture): nothing flushes at exit
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, descriptor)
    os.close(devnull)


class _ClosedOutput(io.TextIOBase):
    """Standard output for a process started without one (``hframe-id models >&-``), where
    Python sets ``sys.stdout`` to None: ``print`` then dropped the output without a word and
    the final flush ended in an AttributeError traceback. Writing fails with EBADF instead,
    reported as one error line, as standard output on a full disk is."""

    def write(self, text: str) -> int:
        raise OSError(errno.EBADF, os.strerror(errno.EBADF))


def main(argv: Sequence[str] | None = None) -> int:
    """The ``hframe-id`` command: parse ``argv`` (default: the process's arguments), run the
    chosen subcommand and return its exit status (0 success, 1 a fit or check that failed,
    2 bad input, 130 Ctrl-C or SIGTERM, each reported in one line).

    Without ``argv`` the command is the process (the console script, ``python -m
    hframe_id``): if a model or controller file left a thread running, the process ends
    with the status at once rather than wait for it (``_end_despite_threads``).
    """
    if sys.stdout is None:  # started without one: ``hframe-id models >&-``
        sys.stdout = _ClosedOutput()
    code = _command(sys.argv[1:] if argv is None else list(argv))
    if argv is None:
        _end_despite_threads(code)
    return code


def _end_despite_threads(code: int) -> None:
    """End the process with ``code`` now if a thread that a model or controller file started
    still runs: at exit Python waits for every thread that is not a daemon, so a file's
    ``threading.Thread(target=...).start()`` would keep the finished command alive for as
    long as the thread runs (for ever, for a server loop). The exit handlers (the native-code
    cache's scratch folder) are run and the output flushed first, then ``os._exit``, which
    does not wait. A command that succeeded or reported a failed check says so in one
    warning line; a refused one already has its one error line."""
    waiting = [
        t
        for t in threading.enumerate()
        if t is not threading.main_thread() and t.is_alive() and not t.daemon
    ]
    if not waiting:
        return
    from hframe_id.models.user import threads_left_running  # loaded: the files were

    left = threads_left_running()
    if not left:
        return  # the command's own, which it ends itself
    if code in (0, 1):
        file, thread = left[0]
        print(
            f"hframe-id: warning: {file} left a thread running ({shown(thread.name)}); "
            "the command ends without waiting for it",
            file=sys.stderr,
        )
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # closed (a broken pipe), or a full disk: as at exit
            pass
    os._exit(code)


def _command(argv: list[str]) -> int:
    """``main``'s work: the subcommand run and every way it ends reported."""
    try:
        with signals.handled(), outputs.command(argv):
            try:
                # Ctrl-C while the command's module is imported: one line too
                parser = build_parser(chosen_command(argv))
                args = parser.parse_args(argv)  # a numeric option out of range: OptionError
                with (
                    warnings.catch_warnings(),
                    progress.library_messages(getattr(args, "quiet", False)),
                ):
                    warnings.showwarning = _one_line_warning
                    model_files.load(args)
                    code = int(args.handler(args) or 0)
                signals.check()  # a signal whose exception was lost in C code
                sys.stdout.flush()  # a full disk or a closed pipe shows here, not at exit
                return code
            except Exception:
                signals.check()  # the interrupt, come out of C code as another exception
                raise
    except HframeIdError as err:
        print(f"hframe-id: error: {bounded_message(err)}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into e.g. `head`, which stopped reading
        sys.stderr.close()
        return 0
    except OSError as err:  # one no command handles, e.g. standard output on a full disk
        problem = err.strerror or str(err)
        # without a file name: a stream's write, standard output's (files are written
        # through Staging or the recording writers, which name them)
        where = shown(str(err.filename)) if err.filename else "standard output"
        _detach_stdout()
        line = f"{where}: {problem}"
        print(f"hframe-id: error: {bounded_message(line)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as err:
        detail = f": {err}" if str(err) else " (Ctrl-C)"
        print(f"hframe-id: interrupted{detail}", file=sys.stderr)
        return signals.EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
