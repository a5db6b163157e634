"""What a recording's rig metadata say of its channels: the voltages the plant saw (the
rig's DAC), each channel's default noise level, and the checks that recordings fitted
jointly come from one rig. The recording on a model's channels is a
:class:`hframe_id.fitting.dataset.Dataset`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from hframe_id.errors import FitError
from hframe_id.models import Model
from hframe_id.recordings.recording import Recording
from hframe_id.recordings.sensors import ENCODER_OUTPUTS, LASER_OUTPUTS, SensorModel

#: Rig metadata keys that identify a physical rig (or the sim plant); recordings fitted
#: jointly must agree on every one of them that both carry.
RIG_IDENTITY_KEYS = (
    "rig_id",
    "name",
    "serial",
    "backend",
    "plant",
    "encoder_counts_per_rev",
    "laser_noise_std_m",
    "dac_bits",
)


def rig_dac(rig: dict) -> SensorModel | None:
    """The rig's DAC (``dac_bits``, ``dac_min_v`` [V], ``dac_max_v`` [V] in its metadata) as a
    sensor model, or None when the metadata do not describe one."""
    if not all(k in rig for k in ("dac_bits", "dac_min_v", "dac_max_v")):
        return None
    return SensorModel(
        dac_bits=int(rig["dac_bits"]),
        dac_min_v=float(rig["dac_min_v"]),
        dac_max_v=float(rig["dac_max_v"]),
    )


def applied_inputs(recording: Recording) -> np.ndarray:
    """Voltages the plant saw [V]: the recording's applied voltages if it has them, else the
    commanded ones through the rig's DAC when its metadata describe one (``rig_dac``)."""
    applied = getattr(recording, "applied", None)
    if applied is not None:
        return np.asarray(applied, dtype=float)
    dac = rig_dac(recording.rig)
    if dac is not None:
        return dac.dac(recording.inputs)
    return np.asarray(recording.inputs, dtype=float)


def encoder_step(recording: Recording, output: str) -> float:
    """Quantization step [rad] of an encoder channel (angles), 0 for other channels or when
    the rig metadata do not give the resolution."""
    counts = recording.rig.get("encoder_counts_per_rev")
    if not output.startswith("phi") or counts is None:
        return 0.0
    return 2 * math.pi / float(counts)


def data_noise_std(recording: Recording, output: str) -> float:
    """Noise std of an output estimated from the data alone [SI]: the robust spread of its
    second differences, sigma = 1.4826 MAD(d2 y) / sqrt(6) (white noise e gives d2 e a variance
    of 6 sigma^2; a motion smooth over a few samples adds little to d2 y)."""
    j = recording.output_names.index(output)
    y = recording.outputs[:, j]
    second = np.diff(y[recording.valid[:, j] & np.isfinite(y)], 2)
    sigma = 1.4826 * float(np.median(np.abs(second - np.median(second)))) / math.sqrt(6)
    if not sigma > 0:
        # Quantized or piecewise-constant data: the median difference is 0; use the rms.
        sigma = float(np.sqrt(np.mean(second**2)) / math.sqrt(6)) if second.size else 0.0
    if not sigma > 0:
        raise FitError(
            f"{recording.name()}: cannot estimate the noise of {output} from the data (it does "
            f"not vary); give channel_std for {output}"
        )
    return sigma


def default_channel_std(recording: Recording, output: str, model: Model | None = None) -> float:
    """Noise std of an output channel [SI]: the rig's declaration (``noise_std_<output>``: a
    value, or "estimate": ``data_noise_std``), else the sensor noise the ``model``'s
    ``Output`` declares, else the H-frame rig's sensors (encoder quantization, laser noise)
    from its metadata."""
    rig = recording.rig
    declared = recording.declared_noise_std(output)
    if declared == "estimate":
        return data_noise_std(recording, output)
    if declared is not None:
        return float(declared)
    sensor = None if model is None else model.declaration.output_noise_std(output)
    if sensor is not None:
        return float(sensor)
    if output not in ENCODER_OUTPUTS + LASER_OUTPUTS:
        raise FitError(
            f"{recording.name()}: rig metadata declare no noise_std_{output}; give channel_std "
            f"for {output} (or noise_std in the model's Output declaration)"
        )
    if output.startswith("phi"):
        counts = rig.get("encoder_counts_per_rev")
        if counts is None:
            raise FitError(
                f"{recording.name()}: rig metadata lack encoder_counts_per_rev; give "
                f"channel_std for {output}"
            )
        return 2 * math.pi / float(counts) / math.sqrt(12)
    noise = rig.get("laser_noise_std_m")
    if noise is None or not float(noise) > 0:
        raise FitError(
            f"{recording.name()}: rig metadata lack laser_noise_std_m; give channel_std for "
            f"{output}"
        )
    return float(noise)


def check_rigs(recordings: Sequence[Recording]) -> None:
    """Raise ``FitError`` unless the ``recordings`` share their model variant, their rig (every
    ``RIG_IDENTITY_KEYS`` entry both carry) and their sample period [s]."""
    first = recordings[0]
    for rec in recordings[1:]:
        if rec.variant != first.variant:
            raise FitError(
                f"cannot fit recordings of different model variants jointly: "
                f"{first.name()} is {first.variant}, {rec.name()} is {rec.variant}"
            )
        for key in RIG_IDENTITY_KEYS:
            if key in first.rig and key in rec.rig and str(first.rig[key]) != str(rec.rig[key]):
                raise FitError(
                    f"cannot fit recordings of different rigs jointly: rig {key} is "
                    f"{first.rig[key]!r} in {first.name()} but {rec.rig[key]!r} in {rec.name()}"
                )
        if not math.isclose(rec.sample_period_s, first.sample_period_s, rel_tol=1e-9):
            raise FitError(
                f"recordings have different sample periods: {first.sample_period_s} s "
                f"({first.name()}) and {rec.sample_period_s} s ({rec.name()})"
            )
