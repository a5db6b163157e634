"""Where report figures are drawn: here, in order (``InlineDrawer``), or in worker processes
started before the work whose results they show (``ProcessDrawer``).

Drawing the shipped 4 V fit's figures costs about as much as its 1.2 s solve: importing
matplotlib 0.47 s, the correlation map 0.29 s, the experiment's figure 0.28 s (this machine,
quiet). A worker started with the command imports matplotlib while this process reads the
inputs and imports the fitter (both single-threaded; 0.45 s, against the worker's 0.55 s
with its own start, so the import overlaps the solve's first 0.1 s and slows it by about as
much), forks a copy of itself, and both wait without using the CPU while the fit solves on
every core; then they draw the figures side by side while the report is written.
``finish`` waits for every figure and raises the first failure, so the caller can drop a
half-drawn plots folder.
"""

from __future__ import annotations

import contextlib
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


def _serve(connections: list, prepare: Callable[[], None] | None) -> None:
    """The worker: ``prepare()`` (imports), then one copy per connection (the others forked
    with the imports done), each drawing the ``(function, args)`` it receives and answering
    None or the exception, until None arrives or the command's end of its pipe closes."""
    os.nice(WORKER_NICENESS)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the command handles Ctrl-C and stops it
    if prepare is not None:
        prepare()
    mine, forked = connections[0], False
    for connection in connections[1:]:
        if os.fork() == 0:
            mine, forked = connection, True
            break
    for connection in connections:
        if connection is not mine:
            connection.close()
    _answer(mine)
    if forked:
        os._exit(0)  # a forked copy leaves without the spawned process's exit handlers


def _answer(connection) -> None:
    """Draw each task received on ``connection`` until None or the end of the pipe: the
    command is gone (interrupted), also when an answer finds the pipe closed, which used to
    end the worker with a traceback under the command's "interrupted" line."""
    with contextlib.suppress(EOFError, OSError):
        while (task := connection.recv()) is not None:
            function, args = task
            try:
                function(*args)
            except Exception as err:  # noqa: BLE001 - every failure goes back to the command
                connection.send(err)
            else:
                connection.send(None)


class FigureWorkerError(RuntimeError):
    """A figure worker process ended before drawing every figure."""


class ProcessDrawer:
    """Draws figures in worker processes: one spawned, which imports matplotlib, and copies
    of it forked after the import (where the system can fork); a context manager.

    The functions and their arguments are pickled: module-level functions of plain data
    (``hframe_id.fitting.report_figures``). The worker is spawned, so the calling program's
    main module must guard its work with ``if __name__ == "__main__":`` (the console script
    and ``python -m hframe_id`` do).
    """

    def __init__(self, prepare: Callable[[], None] | None = None, workers: int = 2) -> None:
        """Start the workers; they call ``prepare()`` first (e.g. import matplotlib)."""
        import multiprocessing

        context = multiprocessing.get_context("spawn")
        copies = workers if hasattr(os, "fork") else 1
        pipes = [context.Pipe() for _ in range(copies)]
        process = context.Process(
            target=_serve,
            args=([child for _, child in pipes], prepare),
            name="hframe-id figures",
            daemon=True,
        )
        process.start()
        for _, child in pipes:
            child.close()  # the workers' ends: only the workers hold them now
        self._connections = [connection for connection, _ in pipes]
        self._pending = [0] * copies

    def draw(self, function: Callable[..., None], *args: Any) -> None:
        """Queue ``function(*args)`` on the worker with the fewest figures queued."""
        index = self._pending.index(min(self._pending))
        self._connections[index].send((function, args))
        self._pending[index] += 1

    def _collect(self) -> list[BaseException]:
        """Wait for the answer to every queued figure: the failures."""
        failures: list[BaseException] = []
        for index, connection in enumerate(self._connections):
            pending, self._pending[index] = self._pending[index], 0
            for _ in range(pending):
                try:
                    answer = connection.recv()
                except EOFError:
                    failures.append(
                        FigureWorkerError("a figure worker ended before drawing its figures")
                    )
                    break
                if answer is not None:
                    failures.append(answer)
        return failures

    def finish(self) -> None:
        """Wait for every queued figure, then raise the first failure: when this returns or
        raises, no worker draws any more."""
        if failures := self._collect():
            raise failures[0]

    def discard(self) -> None:
        """Wait for the figures being drawn, ignoring how they ended (the caller is failing
        already and removes what they drew)."""
        self._collect()

    def __enter__(self) -> ProcessDrawer:
        return self

    def __exit__(self, kind: object, *exc: object) -> None:
        self.discard()
        for connection in self._connections:
            if kind is None:
                with contextlib.suppress(OSError):  # a worker that ended has no pipe
                    connection.send(None)  # the workers exit by themselves; nothing waits
            connection.close()
