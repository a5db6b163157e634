"""Checks before any validation work: the parameter files can produce the recordings' signals,
and the recordings come from one rig.

A parameter file of another variant is fine when its model has the recordings' inputs and
outputs (an ``hframe-20`` set on ``hframe-8`` records: u1, u2 -> phi1, phi2, x, y); what is
compared is the signal names, not the variant names.
"""

from __future__ import annotations

from collections.abc import Sequence

from hframe_id.errors import OptionError
from hframe_id.fitting.experiment import RIG_IDENTITY_KEYS
from hframe_id.models import build_model
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording

#: Rig metadata that name one physical rig: the fitter's identity keys and the serial number.
RIG_KEYS = ("serial_number", *RIG_IDENTITY_KEYS)


def check_same_rig(recordings: Sequence[Recording]) -> None:
    """Raise ``OptionError`` unless every recording carries the same rig identity.

    Only keys that both recordings carry are compared (``RIG_KEYS``).
    """
    if not recordings:
        raise OptionError("no recordings to validate on")
    first = recordings[0]
    for rec in recordings[1:]:
        for key in RIG_KEYS:
            if key in first.rig and key in rec.rig and str(first.rig[key]) != str(rec.rig[key]):
                raise OptionError(
                    f"recordings of different rigs: rig {key} is {first.rig[key]!r} in "
                    f"{first.name()} but {rec.rig[key]!r} in {rec.name()}"
                )


def check_signals(params: ParameterSet, recording: Recording) -> None:
    """Raise ``OptionError`` unless the model of ``params`` takes the recording's inputs (same
    names, same order) and produces outputs that the recording measures."""
    model = build_model(params.variant)
    inputs = tuple(s.name for s in model.inputs)
    outputs = [s.name for s in model.outputs]
    where = f"{params.where()} ({params.variant})"
    if tuple(recording.input_names) != inputs:
        raise OptionError(
            f"{where} takes inputs {list(inputs)}, but {recording.name()} has "
            f"{list(recording.input_names)}"
        )
    missing = [name for name in outputs if name not in recording.output_names]
    if missing:
        raise OptionError(
            f"{where} produces outputs {outputs}; {recording.name()} does not measure "
            f"{', '.join(missing)} (it has {list(recording.output_names)})"
        )


def check_inputs(parameter_sets: Sequence[ParameterSet], recordings: Sequence[Recording]) -> None:
    """Every check above, for every parameter set against every recording."""
    check_same_rig(recordings)
    for params in parameter_sets:
        for rec in recordings:
            check_signals(params, rec)
