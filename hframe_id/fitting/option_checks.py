"""One-line checks of option values, shared by the option classes of the fitter's links
(each raises :class:`~hframe_id.errors.OptionError` naming the option and the value given),
and what a set of settings changes from its defaults.
"""

from __future__ import annotations

import math
import numbers
import sys
from dataclasses import fields
from typing import Any

from hframe_id.errors import OptionError, shown


def positive(name: str, value: Any, integer: bool = False) -> None:
    """``value`` is a finite number > 0 (a whole number with ``integer``; never a bool)."""
    _number(name, value, integer)
    _finite(name, value, "> 0")
    if not value > 0:
        raise OptionError(f"{name} must be > 0, got {shown(value)}")


def nonnegative(name: str, value: Any, integer: bool = False) -> None:
    """``value`` is a finite number >= 0 (a whole number with ``integer``; never a bool)."""
    _number(name, value, integer)
    _finite(name, value, ">= 0")
    if not value >= 0:
        raise OptionError(f"{name} must be >= 0, got {shown(value)}")


def _finite(name: str, value: Any, bound: str) -> None:
    """``value`` (a number) is finite, else an error saying it must be ``bound`` too."""
    if not math.isfinite(value):
        raise OptionError(f"{name} must be a finite number {bound}, got {shown(value)}")


def _number(name: str, value: Any, integer: bool) -> None:
    """``value`` is a number (a whole one with ``integer``: Python's or NumPy's), not a
    bool."""
    kind = numbers.Integral if integer else numbers.Real
    if isinstance(value, bool) or not isinstance(value, kind):
        raise OptionError(
            f"{name} must be a {'whole ' if integer else ''}number, got {shown(value)}"
        )


def fraction(name: str, value: Any) -> None:
    """``value`` is a number in the open interval (0, 1)."""
    positive(name, value)
    if value >= 1:
        raise OptionError(f"{name} must be < 1, got {shown(value)}")


def one_of(name: str, value: Any, choices: tuple[str, ...]) -> None:
    """``value`` is one of ``choices``."""
    if value not in choices:
        raise OptionError(f"{name} must be one of {', '.join(choices)}, got {shown(value)}")


def names(name: str, value: Any) -> tuple[str, ...]:
    """``value`` as a tuple of non-empty names (a single string is refused)."""
    items = None if isinstance(value, str) else as_tuple(value)
    if items is None or not all(isinstance(v, str) and v for v in items):
        raise OptionError(
            f"{name} must be a sequence of parameter names or patterns, got {shown(value)}"
        )
    return items


def check_numbers(
    settings: Any,
    prefix: str,
    counts: tuple[str, ...] = (),
    fractions: tuple[str, ...] = (),
    may_be_zero: tuple[str, ...] = (),
    skip: tuple[str, ...] = (),
) -> None:
    """Each field of the dataclass instance ``settings`` (but ``skip``) a finite number > 0,
    named ``<prefix>.<field>`` in the message: whole numbers among ``counts``, in (0, 1)
    among ``fractions``, >= 0 among ``may_be_zero``."""
    for f in fields(settings):
        if f.name in skip:
            continue
        name, value = f"{prefix}.{f.name}", getattr(settings, f.name)
        if f.name in fractions:
            fraction(name, value)
        elif f.name in may_be_zero:
            nonnegative(name, value, integer=f.name in counts)
        else:
            positive(name, value, integer=f.name in counts)


def changed_fields(settings: Any) -> dict[str, Any]:
    """The fields of the dataclass instance ``settings`` that differ from its class's
    defaults, by name (for a fit's provenance: ``GaussNewtonSettings``,
    ``StrategySettings``)."""
    default = type(settings)()
    return {
        f.name: _plain(getattr(settings, f.name))
        for f in fields(settings)
        if getattr(settings, f.name) != getattr(default, f.name)
    }


def _plain(value: Any) -> Any:
    """``value`` with NumPy numbers as Python's (a parameter file holds plain data). NumPy
    is not imported for it: a NumPy number exists only once NumPy is (``fit --help`` reads
    these modules and needs none of it)."""
    if isinstance(value, tuple | list):
        return type(value)(_plain(v) for v in value)
    numpy = sys.modules.get("numpy")
    return value.item() if numpy is not None and isinstance(value, numpy.generic) else value


def as_tuple(value: Any) -> tuple | None:
    """``value``'s items as a tuple, None if it has none (a number)."""
    try:
        return tuple(value)
    except TypeError:
        return None
