"""Ctrl-C and SIGTERM in the command line (issue 27, item 6).

``handled()`` installs, for the duration of one command, a handler of SIGINT and SIGTERM
that records the signal and raises ``Interrupted`` (a ``KeyboardInterrupt``) in the main
thread. SIGTERM (``kill``, a job scheduler's stop) then ends a command exactly as Ctrl-C
does: the exception unwinds through the outputs' ``Staging`` (``outputs.written_together``),
which removes everything not yet put in place, and the command line exits 130 with one line.

The signal is recorded as well as raised because an exception raised while C code calls back
into Python (CasADi converting an array, a Dask callback) can come out as another exception
(``SystemError``) or be swallowed by a library's ``except Exception``. ``check()`` raises
it again: the command line calls it when a command returns or fails, so that the run ends as
interrupted whatever became of the first exception, and ``written_together`` calls it before
it puts outputs in place, so that an interrupted run never commits them. The record is
module state because a signal handler has nowhere else to put it; ``handled()`` clears it
on entry.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from hframe_id.errors import Interrupted

#: The signals that end a command: Ctrl-C and ``kill``'s default.
SIGNALS = (signal.SIGINT, signal.SIGTERM)

_received: list[str] = []  # names of the signals received during the current command


def _handle(signum: int, frame: object) -> None:
    name = signal.Signals(signum).name
    _received.append(name)
    raise Interrupted(f"{name} received")


def check() -> None:
    """Raise ``Interrupted`` if a signal was received during the current command (even one
    whose exception was lost on its way through C code)."""
    if _received:
        raise Interrupted(f"{_received[0]} received")


@contextmanager
def handled() -> Iterator[None]:
    """SIGINT and SIGTERM raise ``Interrupted`` in the block (main thread only; elsewhere
    the block runs with the handlers it has); the previous handlers are put back after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _received.clear()
    previous = {signum: signal.signal(signum, _handle) for signum in SIGNALS}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
