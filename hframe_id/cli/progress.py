"""Progress on stderr for work that can take more than a few seconds (issue 27, item 7).

The rule is the fit's (``fit_command``): plain lines on stderr, none with ``--quiet``
(``add_quiet_option``). ``Progress.line`` prints one. A step whose length is not known in
advance (a simulation of a whole run, which is one call into C code) runs under
``Progress.slow``: it is announced only if it is still running after ``ANNOUNCE_AFTER_S``
(from a timer thread; CasADi releases the GIL while it computes), and then its end is
reported with its time, so a short run prints nothing and a long one is never silent.

The library's own progress messages (the ``hframe_id`` logger at INFO: ``hframe_id.native``
announces a long compile) are shown the same way for the duration of a command
(``library_messages``), and hidden with ``--quiet``.
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

#: Seconds a step may run before it is announced.
ANNOUNCE_AFTER_S = 2.0


def add_quiet_option(parser: argparse.ArgumentParser) -> None:
    """``--quiet``: no progress lines on stderr."""
    parser.add_argument("--quiet", action="store_true", help="no progress lines on stderr")


class Progress:
    """Progress lines on stderr, or none if ``quiet``."""

    def __init__(self, quiet: bool) -> None:
        self.quiet = quiet

    def line(self, text: str) -> None:
        """Print ``text`` as one line on stderr (not if quiet)."""
        if not self.quiet:
            print(text, file=sys.stderr, flush=True)

    @contextmanager
    def slow(self, what: str) -> Iterator[None]:
        """Run the block; if it is still running after ``ANNOUNCE_AFTER_S``, print
        ``what ...`` then, when it ends normally, ``what: done in T s``."""
        announced = threading.Event()

        def announce() -> None:
            announced.set()
            self.line(f"{what} ...")

        start = time.perf_counter()
        timer = threading.Timer(ANNOUNCE_AFTER_S, announce)
        timer.daemon = True
        if not self.quiet:
            timer.start()
        try:
            yield
        finally:
            timer.cancel()
        if announced.is_set():
            self.line(f"{what}: done in {time.perf_counter() - start:.1f} s")


@contextmanager
def library_messages(quiet: bool) -> Iterator[None]:
    """Show the ``hframe_id`` logger's INFO messages as lines on stderr in the block (none
    if ``quiet``); the logger's level and handlers are put back afterwards."""
    if quiet:
        yield
        return
    logger = logging.getLogger("hframe_id")
    handler = logging.StreamHandler(sys.stderr)  # the stream of this command (pytest's)
    handler.setFormatter(logging.Formatter("%(message)s"))
    level = logger.level
    logger.setLevel(logging.INFO)
    logger.addHandler(handler)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
