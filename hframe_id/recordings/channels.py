"""Declared channels of a ``hframe_id.SignalSample`` recording (log format 1.1).

A rig of any kind declares its channels in the ``rig`` metadata: model inputs and outputs
with their SI units, outputs that carry a validity flag, and extra recorded signals that are
neither (a reference trajectory, say). Each channel is one field of the sample message, named
as the channel; an output ``y`` with a validity flag also has the field ``y_valid``.
``Channels`` checks a declaration, writes it as metadata and builds the JSON Schema of the
sample messages from it, so that writer and reader derive both from the same place.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from hframe_id.errors import shown
from hframe_id.recordings import log_format as fmt

#: A channel name: an ASCII identifier, so that it is a plain field name in any MCAP tool.
NAME_PATTERN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
#: Suffix of an output's validity field.
VALID_SUFFIX = "_valid"
#: Sample fields that are not channels.
RESERVED_FIELDS = ("sequence", "device_time_us")

#: SI units a channel may have ("1": dimensionless).
SI_UNITS = (
    "1",
    "s",
    "m",
    "rad",
    "m/s",
    "rad/s",
    "m/s^2",
    "rad/s^2",
    "V",
    "A",
    "N",
    "N.m",
    "kg",
    "W",
    "Pa",
    "K",
)

#: Units of the H-frame rig's channels (``RigSample``), by model signal name.
HFRAME_UNITS = {"u1": "V", "u2": "V", "phi1": "rad", "phi2": "rad", "x": "m", "y": "m"}


@dataclass(frozen=True)
class Channels:
    """The channels of a ``SignalSample`` recording, in message field order.

    Attributes
    ----------
    inputs, input_units : model inputs and their SI units (one each, same order).
    outputs, output_units : model outputs and their SI units.
    signals, signal_units : extra recorded signals (not model inputs or outputs).
    validity : outputs whose samples carry a ``<output>_valid`` flag.

    Raises ValueError naming the offending item when the declaration is inconsistent.
    """

    inputs: tuple[str, ...]
    input_units: tuple[str, ...]
    outputs: tuple[str, ...]
    output_units: tuple[str, ...]
    signals: tuple[str, ...] = ()
    signal_units: tuple[str, ...] = ()
    validity: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not self.inputs or not self.outputs:
            raise ValueError("a recording needs at least one input and one output channel")
        for kind, names, units in (
            ("input", self.inputs, self.input_units),
            ("output", self.outputs, self.output_units),
            ("signal", self.signals, self.signal_units),
        ):
            if len(names) != len(units):
                raise ValueError(
                    f"{len(names)} {kind}(s) ({','.join(names)}) but {len(units)} "
                    f"{kind}_units ({','.join(units)})"
                )
            for name, unit in zip(names, units, strict=True):
                if not NAME_PATTERN.match(name) or name.endswith(VALID_SUFFIX):
                    raise ValueError(
                        f"{kind} name {shown(name)} must be an identifier (letters, digits, '_'; "
                        f"not starting with a digit) not ending in {VALID_SUFFIX!r}"
                    )
                if unit not in SI_UNITS:
                    raise ValueError(
                        f"{kind} {name}: unit {shown(unit)} is not an SI unit of the "
                        f"log format ({', '.join(SI_UNITS)})"
                    )
        names = self.inputs + self.outputs + self.signals
        clashes = sorted(
            {n for n in names if names.count(n) > 1} | set(names) & set(RESERVED_FIELDS)
        )
        if clashes:
            raise ValueError(f"channel name(s) {', '.join(clashes)} used twice or reserved")
        stray = [n for n in self.validity if n not in self.outputs]
        if stray:
            raise ValueError(f"output_validity names {', '.join(stray)}, which are not outputs")

    @classmethod
    def from_rig(cls, rig: Mapping[str, Any]) -> Channels:
        """The declaration in a (decoded) ``rig`` metadata record."""

        def names(key: str) -> tuple[str, ...]:
            return fmt.split_list(rig.get(key, ""))

        return cls(
            inputs=names("inputs"),
            input_units=names("input_units"),
            outputs=names("outputs"),
            output_units=names("output_units"),
            signals=names("signals"),
            signal_units=names("signal_units"),
            validity=names("output_validity"),
        )

    def metadata(self) -> dict[str, Any]:
        """The declaration as ``rig`` metadata keys (optional ones only when used)."""
        meta: dict[str, Any] = {
            "inputs": list(self.inputs),
            "input_units": list(self.input_units),
            "outputs": list(self.outputs),
            "output_units": list(self.output_units),
        }
        if self.signals:
            meta["signals"] = list(self.signals)
            meta["signal_units"] = list(self.signal_units)
        if self.validity:
            meta["output_validity"] = list(self.validity)
        return meta

    def schema(self) -> dict[str, Any]:
        """JSON Schema of this recording's ``hframe_id.SignalSample`` messages."""
        number = ["number", "null"]
        props: dict[str, Any] = {
            "sequence": {"type": "integer", "minimum": 0, "description": "sample counter"},
            "device_time_us": {
                "type": "integer",
                "description": "clock at the sample [us] (only differences matter)",
            },
        }
        for name, unit in zip(self.inputs, self.input_units, strict=True):
            props[name] = {
                "type": number,
                "description": f"input {name} [{unit}], applied right after this sample and "
                "held until the next",
            }
        for name, unit in zip(self.outputs, self.output_units, strict=True):
            props[name] = {
                "type": number,
                "description": f"output {name} [{unit}] measured at this sample; null: no value",
            }
            if name in self.validity:
                props[name + VALID_SUFFIX] = {
                    "type": "boolean",
                    "description": f"output {name} may be used at this sample",
                }
        for name, unit in zip(self.signals, self.signal_units, strict=True):
            props[name] = {
                "type": number,
                "description": f"signal {name} [{unit}], recorded but not a model input/output",
            }
        return {
            "$schema": "https://json-schema.org/draft/2020-12/schema",
            "title": fmt.SIGNAL_SAMPLE_SCHEMA_NAME,
            "description": "One sample of a rig whose channels, with their SI units, are "
            "declared in the rig metadata (hframe-id log format 1.1)",
            "type": "object",
            "properties": props,
            "required": list(props),
            "additionalProperties": False,
        }
