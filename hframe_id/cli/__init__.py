"""The ``hframe-id`` command line: one entry point, one module per subcommand.

Each command module defines ``register(subparsers)``, which adds its parser and sets
``handler`` to a function ``(args) -> int``. Errors derived from ``HframeIdError`` are printed
as one line (``hframe-id: error: ...``) with exit status 2; nothing is printed from deep inside
a library.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from hframe_id import __version__
from hframe_id.cli import (
    control_command,
    datasets_command,
    export_command,
    fit_command,
    import_command,
    inspect_command,
    linearize_command,
    model_files,
    models_command,
    params_command,
    record_command,
    reduce_command,
    reproduce_command,
    simulate_command,
    validate_command,
)
from hframe_id.errors import HframeIdError

COMMAND_MODULES = (
    models_command,
    params_command,
    linearize_command,
    export_command,
    reduce_command,
    record_command,
    inspect_command,
    import_command,
    datasets_command,
    simulate_command,
    control_command,
    reproduce_command,
    fit_command,
    validate_command,
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hframe-id",
        description="Identify, simulate and control belt-driven H-frame XY stages.",
    )
    parser.add_argument("--version", action="version", version=f"hframe-id {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module in COMMAND_MODULES:
        module.register(subparsers)
    for name in model_files.COMMANDS:
        model_files.add_option(subparsers.choices[name])
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        model_files.load(args)
        return int(args.handler(args) or 0)
    except HframeIdError as err:
        print(f"hframe-id: error: {err}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into e.g. `head`, which stopped reading
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print("hframe-id: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
