"""Units accepted at the import edge and their conversion to the log format's SI units.

A value v in unit ``u`` is ``UNITS[u].factor * v`` in ``UNITS[u].si``. Encoder ``counts``
convert to radians with the encoder's counts per revolution, which the caller supplies.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass

from hframe_id.recordings.channels import SI_UNITS

#: Encoder counts: 2 pi / (counts per revolution) [rad] each.
COUNTS = "counts"


@dataclass(frozen=True)
class Unit:
    """A unit as a multiple of an SI unit of the log format: value [si] = factor * value."""

    si: str
    factor: float


UNITS: dict[str, Unit] = {
    **{name: Unit(name, 1.0) for name in SI_UNITS},
    "ms": Unit("s", 1e-3),
    "us": Unit("s", 1e-6),
    "mm": Unit("m", 1e-3),
    "cm": Unit("m", 1e-2),
    "um": Unit("m", 1e-6),
    "in": Unit("m", 0.0254),
    "deg": Unit("rad", math.pi / 180),
    "rev": Unit("rad", 2 * math.pi),
    "mm/s": Unit("m/s", 1e-3),
    "deg/s": Unit("rad/s", math.pi / 180),
    "rpm": Unit("rad/s", 2 * math.pi / 60),
    "mm/s^2": Unit("m/s^2", 1e-3),
    "deg/s^2": Unit("rad/s^2", math.pi / 180),
    "mV": Unit("V", 1e-3),
    "mA": Unit("A", 1e-3),
    "kN": Unit("N", 1e3),
    "N.mm": Unit("N.m", 1e-3),
    "g": Unit("kg", 1e-3),
}

#: Every unit name ``to_si`` accepts, for help texts.
KNOWN_UNITS = (*UNITS, COUNTS)


def to_si(unit: str, counts_per_rev: float | None = None) -> Unit:
    """The SI unit and factor of ``unit``; ``counts`` need ``counts_per_rev``.

    Raises ValueError naming the unit (and the nearest known one) if it is not known.
    """
    if unit == COUNTS:
        if counts_per_rev is None:
            raise ValueError("unit 'counts' needs the encoder's counts per revolution")
        return Unit("rad", 2 * math.pi / counts_per_rev)
    if unit not in UNITS:
        near = difflib.get_close_matches(unit, KNOWN_UNITS, n=1)
        hint = f" (did you mean {near[0]!r}?)" if near else ""
        raise ValueError(f"unknown unit {unit!r}{hint}; known: {', '.join(KNOWN_UNITS)}")
    return UNITS[unit]
