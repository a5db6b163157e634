"""Run every benchmark section: ``python -m hframe_id.bench [SECTION ...]``."""

from __future__ import annotations

import argparse
import importlib
import platform
import sys

#: Section modules under hframe_id.bench; each has ``run() -> None`` that prints its results.
SECTIONS: tuple[str, ...] = ("simulation", "logging", "fitting")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hframe_id.bench")
    parser.add_argument("sections", nargs="*", metavar="SECTION", help=f"one of {SECTIONS}")
    args = parser.parse_args(argv)
    print(
        f"# hframe-id benchmarks ({platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()})"
    )
    unknown = [name for name in args.sections if name not in SECTIONS]
    if unknown:
        parser.error(f"unknown section(s) {unknown}; valid: {', '.join(SECTIONS)}")
    for name in args.sections or SECTIONS:
        importlib.import_module(f"hframe_id.bench.{name}").run()
    return 0


if __name__ == "__main__":
    sys.exit(main())
