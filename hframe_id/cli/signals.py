"""Ctrl-C, SIGTERM and SIGHUP in the command line (issue 27, item 6).

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

Python runs a signal's handler only between two bytecodes of the main thread, so a long
call into C code (a CasADi simulation of a whole run is one call) would delay it by as long
as the call lasts. The C-level handler does write the signal's number to a wakeup pipe at
once (``signal.set_wakeup_fd``), and a watchdog thread reads it: CasADi releases the GIL
while it computes, so the watchdog runs, and if the main thread has not run the handler
``GRACE_S`` later (and the handler is still this module's: the recorder installs its own,
which stops a recording cleanly) it ends the process itself: it removes the outputs staged
so far (those registered by ``discard_on_exit``), prints the line and exits 130
(``os._exit``: the main thread is inside C code and cannot unwind).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from hframe_id.errors import Interrupted, stopping_signals

#: Seconds the main thread has to run the handler before the watchdog ends the process.
GRACE_S = 0.5
#: Exit status of a command ended by Ctrl-C or SIGTERM (128 + SIGINT, the shells' convention).
EXIT_INTERRUPTED = 130

_received: list[str] = []  # names of the signals received during the current command
_deferring: list[bool] = []  # one entry per ``deferred`` block the main thread is in
_discards: list[Callable[[], None]] = []  # what the watchdog removes before it exits


def _handle(signum: int, frame: object) -> None:
    name = signal.Signals(signum).name
    _received.append(name)
    if not _deferring:
        raise Interrupted(f"{name} received")


def check() -> None:
    """Raise ``Interrupted`` if a signal was received during the current command (even one
    whose exception was lost on its way through C code)."""
    if _received:
        raise Interrupted(f"{_received[0]} received")


@contextmanager
def deferred() -> Iterator[None]:
    """A signal received in the block is raised when the block ends (``check``), not inside
    it: for a step that an exception would leave in a state nothing can clean up (a Dask
    cluster half started). Keep such blocks to seconds."""
    _deferring.append(True)
    try:
        yield
    finally:
        _deferring.pop()
    check()


@contextmanager
def discard_on_exit(discard: Callable[[], None]) -> Iterator[None]:
    """In the block, the watchdog calls ``discard`` (a ``Staging.discard``) before it ends
    the process."""
    _discards.append(discard)
    try:
        yield
    finally:
        _discards.remove(discard)


def _watch(wakeups: int, handled_signals: tuple[signal.Signals, ...]) -> None:
    """The watchdog: read signal numbers from the wakeup pipe until it is closed; end the
    process if the main thread has not run the handler of one of ``handled_signals`` in
    time."""
    ending = {int(signum) for signum in handled_signals}
    while data := os.read(wakeups, 64):
        if not ending.intersection(data):
            continue  # another signal with a Python handler (the model-file timer's)
        time.sleep(GRACE_S)
        if _received:
            continue  # handled: the command is unwinding
        if any(signal.getsignal(signum) is not _handle for signum in handled_signals):
            continue  # a handler of the command's own (the recorder's clean stop)
        for discard in reversed(_discards):
            discard()
        name = signal.Signals(next(iter(ending.intersection(data)))).name
        sys.stderr.write(f"hframe-id: interrupted: {name} received\n")
        sys.stderr.flush()
        os._exit(EXIT_INTERRUPTED)
    os.close(wakeups)


@contextmanager
def handled() -> Iterator[None]:
    """SIGINT and SIGTERM raise ``Interrupted`` in the block, or end the process within
    ``GRACE_S`` if the main thread is in C code (main thread only; elsewhere the block runs
    with the handlers it has). The previous handlers are put back after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _received.clear()
    wakeups, wakeup_writer = os.pipe()
    os.set_blocking(wakeup_writer, False)
    ending = stopping_signals()
    previous = {signum: signal.signal(signum, _handle) for signum in ending}
    previous_writer = signal.set_wakeup_fd(wakeup_writer, warn_on_full_buffer=False)
    watchdog = threading.Thread(
        target=_watch, args=(wakeups, ending), name="hframe-id signals", daemon=True
    )
    watchdog.start()
    try:
        yield
    finally:
        signal.set_wakeup_fd(previous_writer)
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        os.close(wakeup_writer)  # the watchdog reads the end of the pipe and stops
