"""The ``/rig/sample`` messages of a recording as checked arrays, for either sample schema.

``decode_rig_samples`` reads the H-frame rig's fixed fields (``hframe_id.RigSample``),
``decode_signal_samples`` the channels a ``hframe_id.SignalSample`` recording declares. Both
check the first message against the JSON Schema and every message for presence and type of
its fields, and raise ``LogFormatError`` naming the file, the sample and the field.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import jsonschema
import numpy as np

from hframe_id.errors import LogFormatError, shown
from hframe_id.recordings import log_format as fmt
from hframe_id.recordings.channels import HFRAME_UNITS, VALID_SUFFIX, Channels
from hframe_id.recordings.sensors import ENCODER_OUTPUTS, LASER_OUTPUTS

_RIG_SAMPLE_VALIDATOR = jsonschema.Draft202012Validator(fmt.SAMPLE_SCHEMA)
#: The range of integer fields (``sequence``, ``device_time_us``, encoder counts): int64.
INT64_MIN, INT64_MAX = -(2**63), 2**63 - 1
#: The largest integer a number field may hold (beyond it no float can: 1.8e308).
FLOAT_MAX = int(np.finfo(float).max)


@dataclass(frozen=True)
class SampleColumns:
    """Per-sample arrays of a recording, in SI; names and units of each column.

    Attributes
    ----------
    sequence, device_time_us : (N,) sample counter and clock [us], strictly increasing.
    inputs : (N, n_u) finite inputs.
    outputs : (N, n_y) outputs, NaN where there is no value; ``valid`` (N, n_y) where usable.
    signals : (N, n_s) extra signals, NaN where there is no value.
    """

    sequence: np.ndarray
    device_time_us: np.ndarray
    inputs: np.ndarray
    input_names: tuple[str, ...]
    input_units: tuple[str, ...]
    outputs: np.ndarray
    output_names: tuple[str, ...]
    output_units: tuple[str, ...]
    valid: np.ndarray
    signals: np.ndarray
    signal_names: tuple[str, ...] = ()
    signal_units: tuple[str, ...] = ()


def decode_rig_samples(
    where: str, messages: list[dict[str, Any]], rig: dict[str, Any]
) -> SampleColumns:
    """``hframe_id.RigSample`` messages of an H-frame / one-axis rig (``rig.inputs`` among
    u1, u2 [V]; ``rig.outputs`` among phi1, phi2 [rad], x, y [m])."""
    input_names = fmt.split_list(rig["inputs"])
    output_names = fmt.split_list(rig["outputs"])
    bad_inputs = [n for n in input_names if n not in ("u1", "u2")]
    bad_outputs = [n for n in output_names if n not in ENCODER_OUTPUTS + LASER_OUTPUTS]
    twice = len(set(input_names)) < len(input_names) or len(set(output_names)) < len(output_names)
    if not input_names or bad_inputs or not output_names or bad_outputs or twice:
        raise LogFormatError(
            f"{where}: rig.inputs {shown(rig['inputs'])} / rig.outputs "
            f"{shown(rig['outputs'])} must name u1, u2 and phi1, phi2, x, y, each once"
        )
    _check_fields(where, messages, _RIG_SAMPLE_VALIDATOR)
    sequence, device_time_us = _clock(where, messages)
    inputs = np.column_stack([column(where, messages, f"{name}_V", float) for name in input_names])
    if "dac_min_v" in rig and "dac_max_v" in rig:  # ordered numbers (the reader's checks)
        for j, name in enumerate(input_names):
            _check_range(where, sequence, inputs[:, j], f"{name}_V", rig, "dac_min_v", "dac_max_v")
    outputs = np.empty((len(messages), len(output_names)))
    valid = np.ones(outputs.shape, dtype=bool)
    for j, name in enumerate(output_names):
        if name in ENCODER_OUTPUTS:
            column(where, messages, f"encoder{name[-1]}_counts", int)
            outputs[:, j] = column(where, messages, f"{name}_rad", float)
        else:
            outputs[:, j], valid[:, j] = _flagged(
                where, messages, sequence, f"laser_{name}_m", f"laser_{name}_valid"
            )
            if "laser_min_m" in rig and "laser_max_m" in rig:
                # a valid reading is the target inside the range, plus the sensor's noise
                slack = LASER_SLACK_STD * float(rig.get("laser_noise_std_m", 0.0))
                _check_range(
                    where, sequence, np.where(valid[:, j], outputs[:, j], rig["laser_min_m"]),
                    f"laser_{name}_m (valid)", rig, "laser_min_m", "laser_max_m", slack,
                )  # fmt: skip
    return SampleColumns(
        sequence=sequence,
        device_time_us=device_time_us,
        inputs=inputs,
        input_names=input_names,
        input_units=tuple(HFRAME_UNITS[n] for n in input_names),
        outputs=outputs,
        output_names=output_names,
        output_units=tuple(HFRAME_UNITS[n] for n in output_names),
        valid=valid,
        signals=np.empty((len(messages), 0)),
    )


def decode_signal_samples(
    where: str, messages: list[dict[str, Any]], channels: Channels
) -> SampleColumns:
    """``hframe_id.SignalSample`` messages with the fields ``channels`` declares: inputs must
    be finite; an output without a value (null) is invalid at that sample, and one with a
    validity flag is valid where the flag says (a valid sample must have a value)."""
    _check_fields(where, messages, jsonschema.Draft202012Validator(channels.schema()))
    sequence, device_time_us = _clock(where, messages)
    n = len(messages)

    def block(names: Sequence[str], nullable: bool) -> np.ndarray:
        columns = [column(where, messages, name, float, nullable=nullable) for name in names]
        return np.column_stack(columns) if columns else np.empty((n, 0))

    outputs = block(channels.outputs, nullable=True)
    valid = np.isfinite(outputs)
    for j, name in enumerate(channels.outputs):
        if name in channels.validity:
            outputs[:, j], valid[:, j] = _flagged(
                where, messages, sequence, name, name + VALID_SUFFIX
            )
    return SampleColumns(
        sequence=sequence,
        device_time_us=device_time_us,
        inputs=block(channels.inputs, nullable=False),
        input_names=channels.inputs,
        input_units=channels.input_units,
        outputs=outputs,
        output_names=channels.outputs,
        output_units=channels.output_units,
        valid=valid,
        signals=block(channels.signals, nullable=True),
        signal_names=channels.signals,
        signal_units=channels.signal_units,
    )


def _clock(where: str, messages: list[dict[str, Any]]) -> tuple[np.ndarray, np.ndarray]:
    sequence = column(where, messages, "sequence", int)
    device_time_us = column(where, messages, "device_time_us", int)
    _check_increasing(where, "sequence", sequence)
    _check_increasing(where, "device_time_us", device_time_us)
    return sequence, device_time_us


#: How far past its measuring range a valid laser reading may lie, in the laser's noise std.
LASER_SLACK_STD = 10.0


def _check_range(
    where: str,
    sequence: np.ndarray,
    values: np.ndarray,
    field: str,
    rig: dict[str, Any],
    low_key: str,
    high_key: str,
    slack: float = 0.0,
) -> None:
    """Every value within [rig[low_key], rig[high_key]] widened by ``slack``: commands are
    clamped to the DAC range and a valid laser reading is a target inside the range, so a
    value beyond (a voltage of 1e300 V, a reading of 1e300 m) is a broken file, which fits
    ran on for seconds, with numpy overflow warnings, to a failure."""
    low, high = float(rig[low_key]) - slack, float(rig[high_key]) + slack
    outside = (values < low) | (values > high)
    if outside.any():
        i = int(np.argmax(outside))
        raise LogFormatError(
            f"{where}: sample {i} (sequence {sequence[i]}): {field} {values[i]:g} is outside "
            f"rig.{low_key} .. rig.{high_key} [{rig[low_key]:g}, {rig[high_key]:g}]"
        )


def _flagged(
    where: str, messages: list[dict[str, Any]], sequence: np.ndarray, field: str, flag_field: str
) -> tuple[np.ndarray, np.ndarray]:
    """A nullable value and its validity flag; a sample flagged valid must have a value."""
    flag = column(where, messages, flag_field, bool)
    value = column(where, messages, field, float, nullable=True)
    bad = flag & ~np.isfinite(value)
    if bad.any():
        i = int(np.argmax(bad))
        raise LogFormatError(
            f"{where}: sample {i} (sequence {sequence[i]}): {field} is "
            f"{shown(messages[i][field])} although {flag_field} is true"
        )
    return value, flag


def _check_fields(
    where: str, messages: list[dict[str, Any]], validator: jsonschema.Draft202012Validator
) -> None:
    first = messages[0]
    if not isinstance(first, dict):
        raise LogFormatError(f"{where}: sample 0 is not a JSON object")
    error = jsonschema.exceptions.best_match(validator.iter_errors(first))
    if error is not None:
        place = ".".join(str(p) for p in error.absolute_path) or "message"
        raise LogFormatError(
            f"{where}: sample 0 does not match the sample schema: {place}: {error.message}"
        )
    required = set(validator.schema["required"])
    for i, message in enumerate(messages):
        if not isinstance(message, dict) or not required.issubset(message):
            missing = sorted(required - set(message)) if isinstance(message, dict) else ["all"]
            raise LogFormatError(f"{where}: sample {i} lacks field(s) {', '.join(missing)}")


def column(
    where: str, messages: list[dict[str, Any]], name: str, kind: type, nullable: bool = False
) -> np.ndarray:
    """One field of every message as an array of ``kind`` (float: NaN for null if
    ``nullable``, else finite), or a ``LogFormatError`` naming the first bad sample."""
    values = [m[name] for m in messages]
    if kind is bool:
        ok = [type(v) is bool for v in values]
    elif kind is int:
        ok = [type(v) is int and INT64_MIN <= v <= INT64_MAX for v in values]
    else:
        ok = [
            type(v) is float or (type(v) is int and abs(v) <= FLOAT_MAX) or (nullable and v is None)
            for v in values
        ]
    if not all(ok):
        i = ok.index(False)
        expected = {
            bool: "true/false",
            int: "an integer in [-2^63, 2^63)",
            float: "a number",
        }[kind]
        raise LogFormatError(
            f"{where}: sample {i}: {name} must be {expected}, got {shown(values[i])}"
        )
    if kind is float:
        array = np.array([np.nan if v is None else v for v in values], dtype=float)
        if not nullable and not np.isfinite(array).all():
            i = int(np.argmax(~np.isfinite(array)))
            raise LogFormatError(f"{where}: sample {i}: {name} is not finite ({shown(values[i])})")
        return array
    return np.array(values, dtype=bool if kind is bool else np.int64)


def _check_increasing(where: str, name: str, values: np.ndarray) -> None:
    steps = np.diff(values)
    if (steps <= 0).any():
        i = int(np.argmax(steps <= 0)) + 1
        raise LogFormatError(
            f"{where}: {name} must increase strictly, but sample {i} has {values[i]} after "
            f"{values[i - 1]}"
        )
