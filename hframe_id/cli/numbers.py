"""Numeric options with their range declared next to them (issue 27, item 3).

``add_number(group, "--width", float, above=0, ...)`` adds an option whose value is parsed
and range-checked as argparse reads it: a value out of range (or NaN, or infinite) is an
``OptionError`` naming the option and the value, which the command line prints as one
``hframe-id: error:`` line with exit status 2, before the command does any work. A word that
is not a number at all stays argparse's usage error.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from hframe_id.errors import OptionError, shown
from hframe_id.simulation import MAX_SUBSTEPS


def checked(
    option: str,
    kind: type = float,
    *,
    above: float | None = None,
    at_least: float | None = None,
    at_most: float | None = None,
    below: float | None = None,
) -> Callable[[str], float]:
    """An argparse ``type=``: the text as ``kind`` (int or float), finite and within the
    bounds (``above``/``below``: strict; ``at_least``/``at_most``: inclusive)."""

    def parse(text: str):
        value = kind(text)  # ValueError: argparse's "invalid float value"
        problem = None
        if not math.isfinite(value):
            problem = "a finite number"
        elif above is not None and not value > above:
            problem = f"> {above:g}"
        elif at_least is not None and not value >= at_least:
            problem = f">= {at_least:g}"
        elif at_most is not None and not value <= at_most:
            problem = f"<= {at_most:g}"
        elif below is not None and not value < below:
            problem = f"< {below:g}"
        if problem is not None:
            raise OptionError(f"{option} must be {problem}, got {shown(text)}")
        return value

    parse.__name__ = kind.__name__  # argparse names the type in its own messages
    return parse


def add_number(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    option: str,
    kind: type = float,
    *,
    above: float | None = None,
    at_least: float | None = None,
    at_most: float | None = None,
    below: float | None = None,
    **kwargs,
) -> argparse.Action:
    """``parser.add_argument(option, type=checked(...), **kwargs)``: the option and its range
    in one declaration."""
    kind_check = checked(option, kind, above=above, at_least=at_least, at_most=at_most, below=below)
    return parser.add_argument(option, type=kind_check, **kwargs)


def add_substeps(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> argparse.Action:
    """``--substeps``: RK4 substeps per sample, 1 to ``MAX_SUBSTEPS`` (default: automatic)."""
    return add_number(
        parser,
        "--substeps",
        int,
        at_least=1,
        at_most=MAX_SUBSTEPS,
        help="RK4 substeps per sample (default: auto)",
    )
