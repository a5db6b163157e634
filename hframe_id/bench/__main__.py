"""Run every benchmark section: ``python -m hframe_id.bench [SECTION ...] [--no-realistic |
--realistic-only] [--realistic-repeats N]``."""

from __future__ import annotations

import argparse
import importlib
import platform
import sys

#: Section modules under hframe_id.bench; each has ``run()`` that prints its results (the
#: fitting section takes the keyword options built from the flags in ``main``).
SECTIONS: tuple[str, ...] = ("cli", "simulation", "logging", "fitting", "batch")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hframe_id.bench")
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
    args = parser.parse_args(argv)
    print(
        f"# hframe-id benchmarks ({platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()})"
    )
    unknown = [name for name in args.sections if name not in SECTIONS]
    if unknown:
        parser.error(f"unknown section(s) {unknown}; valid: {', '.join(SECTIONS)}")
    options = {
        "fitting": {"realistic": args.realistic, "realistic_repeats": args.realistic_repeats}
    }
    for name in args.sections or SECTIONS:
        importlib.import_module(f"hframe_id.bench.{name}").run(**options.get(name, {}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
