"""Where report figures are drawn: here, in order (``InlineDrawer``), or in a worker process
started before the work whose results they show (``ProcessDrawer``).

Drawing the shipped 4 V fit's figures costs about half as much as its 1.2 s solve: importing
matplotlib 0.47 s, the correlation map 0.29 s, the experiment's figure 0.28 s (this machine,
quiet). A worker started with the command imports matplotlib while this process reads the
inputs and imports the fitter (both single-threaded), then waits without using the CPU while
the fit solves on every core, and draws the figures while the report is written. ``finish``
waits for every figure and raises the first failure, so the caller can drop a half-drawn
plots folder.
"""

from __future__ import annotations

import os
import signal
from collections.abc import Callable
from typing import Any

#: Scheduling priority of the worker (19: the lowest), so that it takes only the cycles the
#: fit leaves free: the fit's kernel runs a thread per core (a worker importing matplotlib at
#: equal priority during the solve slowed the shipped 4 V fit's 1.25 s solve to 2.0-3.5 s).
WORKER_NICENESS = 19


class InlineDrawer:
    """Draws each figure when it is asked for, in this process; a context manager like
    ``ProcessDrawer``."""

    def __enter__(self) -> InlineDrawer:
        return self

    def __exit__(self, *exc: object) -> None:
        pass

    def draw(self, function: Callable[..., None], *args: Any) -> None:
        """Call ``function(*args)`` now."""
        function(*args)

    def finish(self) -> None:
        """Nothing is pending."""

    def discard(self) -> None:
        """Nothing is pending."""


def _serve(connection, prepare: Callable[[], None] | None) -> None:
    """The worker: ``prepare()`` (imports, a first figure), then draw each ``(function,
    args)`` received and answer None or the exception, until None arrives or the command's
    end of the pipe closes."""
    os.nice(WORKER_NICENESS)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the command handles Ctrl-C and stops it
    if prepare is not None:
        prepare()
    while True:
        try:
            task = connection.recv()
        except EOFError:  # the command is gone
            return
        if task is None:
            return
        function, args = task
        try:
            function(*args)
        except Exception as err:  # noqa: BLE001 - every failure goes back to the command
            connection.send(err)
        else:
            connection.send(None)


class FigureWorkerError(RuntimeError):
    """The figure worker process ended before drawing every figure."""


class ProcessDrawer:
    """Draws figures in one spawned worker process; use as a context manager (leaving it
    with an exception stops the worker at once).

    The functions and their arguments are pickled: module-level functions of plain data
    (``hframe_id.fitting.report_figures``).
    """

    def __init__(self, prepare: Callable[[], None] | None = None) -> None:
        """Start the worker; it calls ``prepare()`` first (e.g. imports matplotlib and draws a
        first figure, so that the first real one does not pay for it)."""
        import multiprocessing

        context = multiprocessing.get_context("spawn")
        self._connection, child = context.Pipe()
        self._process = context.Process(
            target=_serve, args=(child, prepare), name="hframe-id figures", daemon=True
        )
        self._process.start()
        child.close()  # the worker's end: only the worker holds it now
        self._pending = 0

    def draw(self, function: Callable[..., None], *args: Any) -> None:
        """Queue ``function(*args)`` on the worker."""
        self._connection.send((function, args))
        self._pending += 1

    def finish(self) -> None:
        """Wait for every queued figure, then raise the first failure: when this returns or
        raises, the worker draws nothing more."""
        from multiprocessing.connection import wait

        pending, self._pending = self._pending, 0
        failures = []
        for _ in range(pending):
            wait([self._connection, self._process.sentinel])
            if not self._connection.poll():
                raise FigureWorkerError(
                    f"the figure worker ended (exit code {self._process.exitcode}) before "
                    "drawing every figure"
                )
            if (answer := self._connection.recv()) is not None:
                failures.append(answer)
        if failures:
            raise failures[0]

    def discard(self) -> None:
        """Stop the worker, drawing or not (the caller is failing already and removes what it
        drew)."""
        self._pending = 0
        self._process.terminate()
        self._process.join()
        self._connection.close()

    def __enter__(self) -> ProcessDrawer:
        return self

    def __exit__(self, kind: object, *exc: object) -> None:
        if self._connection.closed:  # discarded
            return
        if kind is not None or self._pending:
            self.discard()
            return
        self._connection.send(None)  # the worker exits by itself; nothing waits for it
        self._connection.close()
