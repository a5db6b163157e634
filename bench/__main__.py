"""Run every benchmark section: ``python -m bench [SECTION ...] [--no-realistic |
--realistic-only] [--realistic-repeats N] [--fit-starts N] [--fd-starts N]
[--baseline-max-s S] [--batch-rounds N]``.

The sizes of the runs are options here and are passed to the sections' ``run``; no section
reads the environment.
"""

from __future__ import annotations

import argparse
import importlib
import platform
import sys

#: Section modules under bench; each has ``run()`` that prints its results (the
#: fitting and batch sections take the keyword options built from the flags in ``main``).
SECTIONS: tuple[str, ...] = ("cli", "simulation", "logging", "fitting", "batch", "design")


def _count(minimum: int):
    """An argparse type: an integer >= ``minimum``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {value}")
        return value

    return parse


def _seconds(text: str) -> float:
    """An argparse type: a finite time > 0 [s]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite time > 0 s, got {text}")
    return value


def main(argv: list[str] | None = None) -> int:
    """Parse the options, print the machine, run the sections named (all by default)."""
    parser = argparse.ArgumentParser(prog="python -m bench")
    parser.add_argument("sections", nargs="*", metavar="SECTION", help=f"one of {SECTIONS}")
    realistic = parser.add_mutually_exclusive_group()
    realistic.add_argument(
        "--no-realistic",
        dest="realistic",
        action="store_const",
        const="no",
        default="yes",
        help="fitting section: skip the realistic vs matched six-step comparison",
    )
    realistic.add_argument(
        "--realistic-only",
        dest="realistic",
        action="store_const",
        const="only",
        help="fitting section: run only the realistic vs matched comparison (1-3 minutes)",
    )
    parser.add_argument(
        "--realistic-repeats",
        type=int,
        default=1,
        metavar="N",
        help="fitting section: timed runs of the realistic fit, median reported (default 1; "
        "30-60 s each on a quiet machine, ~95 s under load)",
    )
    parser.add_argument(
        "--fit-starts",
        type=_count(1),
        metavar="N",
        help="fitting section: seeded starts for the fitter and the SciPy baseline (default 6)",
    )
    parser.add_argument(
        "--fd-starts",
        type=_count(0),
        metavar="N",
        help="fitting section: starts (the first N, at most --fit-starts) for the baseline's "
        "finite-difference variant (default 2; 0 skips it)",
    )
    parser.add_argument(
        "--baseline-max-s",
        type=_seconds,
        metavar="S",
        help="fitting section: wall-time cap of one baseline run [s] (default 150)",
    )
    parser.add_argument(
        "--batch-rounds",
        type=_count(1),
        metavar="N",
        help="batch section: interleaved rounds of sequential, Dask 1 and Dask 2 workers, "
        "the best time of each kept (default 2)",
    )
    args = parser.parse_args(argv)
    print(
        f"# hframe-id benchmarks ({platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()})"
    )
    unknown = [name for name in args.sections if name not in SECTIONS]
    if unknown:
        parser.error(f"unknown section(s) {unknown}; valid: {', '.join(SECTIONS)}")
    # Sizes left unset keep the section's own default (its module constants).
    sizes = {
        "fitting": {
            "n_starts": args.fit_starts,
            "fd_starts": args.fd_starts,
            "baseline_max_time_s": args.baseline_max_s,
        },
        "batch": {"rounds": args.batch_rounds},
    }
    options = {
        name: {key: value for key, value in given.items() if value is not None}
        for name, given in sizes.items()
    }
    options["fitting"].update(realistic=args.realistic, realistic_repeats=args.realistic_repeats)
    for name in args.sections or SECTIONS:
        importlib.import_module(f"bench.{name}").run(**options.get(name, {}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
