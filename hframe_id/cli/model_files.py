"""``--model-file``: user models (docs/custom-models.md) for every command that reads models."""

from __future__ import annotations

import argparse

#: The commands that take model files: every one that builds, fits or exports a model.
COMMANDS = ("fit", "simulate", "validate", "linearize", "export", "params", "models", "control")


def add_option(parser: argparse.ArgumentParser) -> None:
    """Add ``--model-file`` to a command, or to each of its actions (``params show``)."""
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if actions:
        for action_parser in actions[0].choices.values():
            add_option(action_parser)
        return
    parser.add_argument(
        "--model-file",
        action="append",
        default=[],
        metavar="FILE.py",
        help="a model of your own, declared by its energies (docs/custom-models.md); "
        "repeatable. Its variant can then be used like the built-in ones",
    )


def load(args: argparse.Namespace) -> None:
    """Load and register the model files on the command line (``args.loaded_models``: their
    variant names, in order). The models package (CasADi) is imported only if there are any."""
    paths = getattr(args, "model_file", [])
    if not paths:
        args.loaded_models = []
        return
    from hframe_id.models import load_model_file

    args.loaded_models = [load_model_file(path).name for path in paths]
