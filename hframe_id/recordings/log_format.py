"""The hframe-id log format, version 1 (docs/log-format.md): topics, JSON schemas, metadata.

An MCAP file with JSON messages described by JSON Schema (``jsonschema`` encoding), so that any
MCAP reader (and Foxglove) can open and plot it. Three topics:

- ``/rig/sample``: one flat message per sample, in one of two schemas: ``hframe_id.RigSample``
  (the H-frame rig's fixed fields: sequence, device time, commanded voltages, encoder counts
  and angles, laser positions with validity, limit switches; format 1.0) or
  ``hframe_id.SignalSample`` (any rig: one number per channel declared in the ``rig``
  metadata; format 1.1, ``hframe_id.recordings.channels``).
- ``/rig/event``: start, stop, abort and why, limit trips, link faults, clamping.
- ``/rig/status``: link and timing statistics, about every 100 ms.

Two metadata records, ``rig`` and ``experiment``; MCAP metadata maps strings to strings, so
every value is written as a string (numbers in ``repr`` form, booleans as ``true``/``false``,
lists comma-separated) and parsed back by the reader.
"""

from __future__ import annotations

import json
import math
import re
import sys
from collections.abc import Mapping
from typing import Any

#: Format version written into ``experiment.format_version`` of ``RigSample`` recordings (the
#: lowest version with every feature such a file uses); readers accept the same major.
FORMAT_VERSION = "1.0"
#: Format version of ``SignalSample`` recordings (the minor version that introduced them).
SIGNAL_FORMAT_VERSION = "1.1"
SUPPORTED_MAJOR = 1

SAMPLE_TOPIC = "/rig/sample"
EVENT_TOPIC = "/rig/event"
STATUS_TOPIC = "/rig/status"

SAMPLE_SCHEMA_NAME = "hframe_id.RigSample"
SIGNAL_SAMPLE_SCHEMA_NAME = "hframe_id.SignalSample"
EVENT_SCHEMA_NAME = "hframe_id.RigEvent"
STATUS_SCHEMA_NAME = "hframe_id.RigStatus"

#: Attachment holding the plant parameter file of a sim-rig recording.
PLANT_ATTACHMENT = "plant-parameters.yaml"
PROTOCOL_ATTACHMENT = "protocol.csv"

MOTORS = (1, 2)
AXES = ("x", "y")
LIMIT_SWITCHES = ("x_min", "x_max", "y_min", "y_max")

_NUMBER_OR_NULL = {"type": ["number", "null"]}
_INT_OR_NULL = {"type": ["integer", "null"]}
_BOOL_OR_NULL = {"type": ["boolean", "null"]}


def _sample_properties() -> dict[str, Any]:
    props: dict[str, Any] = {
        "sequence": {"type": "integer", "minimum": 0, "description": "device sample counter"},
        "device_time_us": {
            "type": "integer",
            "description": "device clock at the sample [us] since the device started sampling",
        },
    }
    for m in MOTORS:
        props[f"u{m}_V"] = {
            **_NUMBER_OR_NULL,
            "description": f"voltage commanded to motor {m} right after this sample, held until "
            f"the next one (clamped to the DAC range) [V]; null if the rig has no motor {m}",
        }
    for m in MOTORS:
        props[f"applied{m}_V"] = {
            **_NUMBER_OR_NULL,
            "description": f"voltage the DAC of motor {m} output over the interval that ends "
            "at this sample [V] (after quantization, watchdog and safety stops)",
        }
    for m in MOTORS:
        props[f"encoder{m}_counts"] = {**_INT_OR_NULL, "description": f"encoder {m} [counts]"}
        props[f"phi{m}_rad"] = {**_NUMBER_OR_NULL, "description": f"motor {m} angle [rad]"}
    for a in AXES:
        props[f"laser_{a}_m"] = {
            **_NUMBER_OR_NULL,
            "description": f"laser {a} reading [m]; past its range the sensor holds its last "
            "valid value (null before the first)",
        }
        props[f"laser_{a}_valid"] = {
            **_BOOL_OR_NULL,
            "description": f"laser {a} target inside the measuring range",
        }
    for s in LIMIT_SWITCHES:
        props[f"limit_{s}"] = {**_BOOL_OR_NULL, "description": f"limit switch {s} closed"}
    props["command_sequence"] = {
        **_INT_OR_NULL,
        "description": "sequence of the command in force over the interval that ends here",
    }
    props["watchdog"] = {
        "type": "boolean",
        "description": "device watchdog has dropped the outputs to 0 V",
    }
    return props


SAMPLE_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": SAMPLE_SCHEMA_NAME,
    "description": "One sample of an H-frame / one-axis rig (hframe-id log format 1)",
    "type": "object",
    "properties": _sample_properties(),
    "required": list(_sample_properties()),
    "additionalProperties": False,
}

EVENT_KINDS = ("start", "stop", "abort", "limit", "link_fault", "signal", "clamp", "note")

EVENT_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": EVENT_SCHEMA_NAME,
    "description": "A run event: start, stop, abort (and why), limit trip, link fault",
    "type": "object",
    "properties": {
        "kind": {"type": "string", "enum": list(EVENT_KINDS)},
        "reason": {"type": "string"},
        "sequence": {**_INT_OR_NULL, "description": "sample sequence the event refers to"},
        "device_time_us": _INT_OR_NULL,
    },
    "required": ["kind", "reason", "sequence", "device_time_us"],
    "additionalProperties": False,
}

STATUS_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": STATUS_SCHEMA_NAME,
    "description": "Link and timing statistics since the start of the run",
    "type": "object",
    "properties": {
        "sequence": {"type": "integer", "description": "last sample sequence"},
        "samples": {"type": "integer", "description": "samples received"},
        "lost_samples": {"type": "integer", "description": "sequence numbers never received"},
        "crc_errors": {"type": "integer", "description": "frames dropped for a bad CRC"},
        "late_commands": {
            "type": "integer",
            "description": "intervals the device ran with an older command than the sample's",
        },
        "watchdog": {"type": "boolean", "description": "device watchdog is holding 0 V"},
        "host_latency_mean_us": {
            **_NUMBER_OR_NULL,
            "description": "mean time from receiving a sample to sending its command [us]",
        },
        "host_latency_max_us": _NUMBER_OR_NULL,
        "host_period_jitter_us": {
            **_NUMBER_OR_NULL,
            "description": "standard deviation of the host's sample arrival period [us]",
        },
        "host_period_max_us": _NUMBER_OR_NULL,
        "queue_depth": {
            **_INT_OR_NULL,
            "description": "messages waiting for the writer (null in reproducible runs)",
        },
    },
    "required": [
        "sequence",
        "samples",
        "lost_samples",
        "crc_errors",
        "late_commands",
        "watchdog",
        "host_latency_mean_us",
        "host_latency_max_us",
        "host_period_jitter_us",
        "host_period_max_us",
        "queue_depth",
    ],
    "additionalProperties": False,
}

#: Keys every ``rig`` metadata record has (others are allowed, e.g. serial numbers).
RIG_REQUIRED = (
    "variant",
    "backend",
    "sample_period_s",
    "inputs",
    "outputs",
    "encoder_counts_per_rev",
    "dac_bits",
    "dac_min_v",
    "dac_max_v",
    "laser_min_m",
    "laser_max_m",
)
#: The numeric ``rig`` keys and the range of each, checked when a recording is read (a
#: recording whose encoder has 0 counts per revolution used to fail deep in the fitter):
#: (lowest value, whether the lowest value itself is allowed, highest value allowed); every
#: one finite (a DAC of 100000 bits was refused by the fitter without naming the file).
RIG_NUMBERS: dict[str, tuple[float, bool, float]] = {
    "sample_period_s": (0.0, False, math.inf),
    "encoder_counts_per_rev": (1.0, True, math.inf),
    "dac_bits": (1.0, True, 32.0),
    "laser_noise_std_m": (0.0, True, math.inf),
    "pulley_radius_m": (0.0, False, math.inf),
}
#: ``rig`` keys that hold a range as (low key, high key): low < high.
RIG_RANGES = (
    ("dac_min_v", "dac_max_v"),
    ("laser_min_m", "laser_max_m"),
    ("limit_x_min_m", "limit_x_max_m"),
    ("limit_y_min_m", "limit_y_max_m"),
)
#: Keys every ``rig`` metadata record of a ``SignalSample`` recording has.
SIGNAL_RIG_REQUIRED = (
    "variant",
    "backend",
    "sample_period_s",
    "inputs",
    "input_units",
    "outputs",
    "output_units",
)
#: Prefix of the ``rig`` keys declaring an output's sensor noise: ``noise_std_<output>``.
NOISE_STD_PREFIX = "noise_std_"
#: ``noise_std_<output>`` value asking the fitter to estimate that output's noise.
NOISE_ESTIMATE = "estimate"
#: A model variant name: letters, digits, '-' and '_' (which model it names is for the model
#: that consumes the recording to check).
VARIANT_PATTERN = re.compile(r"[A-Za-z0-9_-]+\Z")
#: Keys every ``experiment`` metadata record has.
EXPERIMENT_REQUIRED = (
    "format_version",
    "protocol",
    "start_time",
    "operator",
    "software_version",
)


def encode_metadata(values: Mapping[str, Any]) -> dict[str, str]:
    """Metadata values as MCAP strings: numbers by repr, booleans true/false, lists with commas."""
    out = {}
    for key, value in values.items():
        if isinstance(value, bool):
            text = "true" if value else "false"
        elif isinstance(value, int | float):
            text = repr(value) if isinstance(value, int) or math.isfinite(value) else "nan"
        elif isinstance(value, list | tuple):
            text = ",".join(str(v) for v in value)
        elif value is None:
            text = ""
        else:
            text = str(value)
        out[str(key)] = text
    return out


#: Metadata keys that stay strings even when they look like numbers.
STRING_KEYS = frozenset(
    {
        "format_version",
        "software_version",
        "serial_number",
        "firmware",
        "start_time",
        "operator",
        "notes",
        "protocol.source",
        "protocol.sha256",
        "variant",
        "backend",
        "name",
        "inputs",
        "input_units",
        "outputs",
        "output_units",
        "signals",
        "signal_units",
        "output_validity",
        "description",
        "citation",
        "source.file",
        "source.format",
        "source.sha256",
        "source.map",
    }
)


def decode_metadata(values: Mapping[str, str]) -> dict[str, Any]:
    """Metadata strings parsed back: integers, floats and booleans where they look like one."""
    return {
        key: text if key in STRING_KEYS else _parse_scalar(text) for key, text in values.items()
    }


def _parse_scalar(text: str) -> Any:
    if text in ("true", "false"):
        return text == "true"
    try:
        value = int(text)
    except ValueError:
        pass
    else:
        # an integer beyond any float stays text: math.isfinite and float() raised an
        # OverflowError on it in every check of a number (rig.encoder_counts_per_rev)
        return value if abs(value) <= sys.float_info.max else text
    try:
        value = float(text)
    except ValueError:
        return text
    return value if text.strip().lower() not in ("inf", "-inf", "infinity") else text


def split_list(value: Any) -> tuple[str, ...]:
    """A comma-separated metadata list as a tuple of names."""
    return tuple(v.strip() for v in str(value).split(",") if v.strip())


def parse_noise_std(value: Any) -> float | str:
    """A ``noise_std_<output>`` metadata value: a float > 0 (SI) or ``"estimate"``.

    Raises ValueError naming the value otherwise.
    """
    if value == NOISE_ESTIMATE:
        return NOISE_ESTIMATE
    if isinstance(value, int | float) and not isinstance(value, bool):
        if math.isfinite(value) and value > 0:
            return float(value)
    raise ValueError(f"must be a number > 0 (SI) or {NOISE_ESTIMATE!r}, got {value!r}")


def schema_bytes(schema: Mapping[str, Any]) -> bytes:
    """A JSON schema as compact UTF-8 JSON, the bytes an MCAP schema record holds."""
    return json.dumps(schema, indent=None, separators=(",", ":")).encode()


def major_version(text: Any) -> int | None:
    """Major number of a version string like ``"1.0"``, or None if it is not one."""
    head = str(text).split(".")[0]
    return int(head) if head.isdigit() else None
