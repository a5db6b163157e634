"""``validate``'s results as a versioned JSON document and as a plain-text table
(docs/validation.md, "JSON output")."""

from __future__ import annotations

import math
from typing import Any

from hframe_id import __version__
from hframe_id.validation.compare import ChannelResult, ValidationResult
from hframe_id.validation.residuals import CorrelationTest

#: Version of the JSON shape; raised when a field changes meaning or disappears.
SCHEMA_VERSION = 1


def _number(value: float) -> float | None:
    """A JSON number, or null for NaN (JSON has no NaN)."""
    return None if value is None or not math.isfinite(value) else float(value)


def _correlation(test: CorrelationTest) -> dict[str, Any]:
    return {
        "lags_samples": [int(k) for k in test.lags_samples],
        "values": [_number(v) for v in test.values],
        "band": _number(test.band),
        "outside": test.outside,
        "allowed_outside": test.allowed_outside,
        "passes": test.passes,
    }


def _channel(channel: ChannelResult) -> dict[str, Any]:
    return {
        "name": channel.name,
        "unit": channel.unit,
        "valid_samples": channel.valid_samples,
        "simulation_fit_percent": _number(channel.simulation_fit_percent),
        "prediction_fit_percent": _number(channel.prediction_fit_percent),
        "residual_rms": _number(channel.residual_rms),
        "residual_passes": channel.passes,
        "autocorrelation": _correlation(channel.autocorrelation),
        "cross_correlation": {
            name: _correlation(test) for name, test in channel.cross_correlation.items()
        },
    }


def to_document(result: ValidationResult) -> dict[str, Any]:
    """The JSON document (plain dicts, lists, numbers; NaN as null)."""
    options = result.options
    return {
        "schema_version": SCHEMA_VERSION,
        "software": f"hframe-id {__version__}",
        "options": {
            "horizon_samples": options.horizon,
            "window_samples": options.window,
            "max_lag_samples": options.max_lag,
            "confidence_percent": 99,
        },
        "parameter_files": [
            {
                "label": label,
                "path": str(params.path) if params.path else None,
                "model": params.variant,
                "title": params.title,
            }
            for label, params in zip(result.labels, result.parameter_sets, strict=True)
        ],
        "recordings": [
            {
                "name": entry.recording.name(),
                "path": str(entry.recording.path) if entry.recording.path else None,
                "samples": entry.recording.n_samples,
                "sample_period_s": entry.recording.sample_period_s,
                "results": [
                    {
                        "parameter_file": run.label,
                        "channels": [_channel(channel) for channel in run.channels],
                    }
                    for run in entry.runs
                ],
            }
            for entry in result.recordings
        ],
    }


def _percent(value: float) -> str:
    return f"{value:8.2f}" if math.isfinite(value) else f"{'-':>8}"


def _verdict(passes: bool | None) -> str:
    return {True: "yes", False: "NO", None: "-"}[passes]


def to_text(result: ValidationResult) -> str:
    """One table per recording: parameter file, channel, fits [%], residual rms, tests."""
    k = result.options.horizon
    lines = []
    for entry in result.recordings:
        rec = entry.recording
        lines.append(f"{rec.name()}: {rec.n_samples} samples, {rec.duration_s:.3f} s")
        width = max(len(label) for label in result.labels)
        lines.append(
            f"  {'parameters':<{width}}  channel  sim fit [%]  {k:>2}-step [%]  "
            f"residual rms      white  indep. of inputs"
        )
        for run in entry.runs:
            for ch in run.channels:
                white = _verdict(ch.autocorrelation.passes)
                lines.append(
                    f"  {run.label:<{width}}  {ch.name:<7}  "
                    f"{_percent(ch.simulation_fit_percent):>11}  "
                    f"{_percent(ch.prediction_fit_percent):>11}  "
                    f"{ch.residual_rms:10.3g} {ch.unit:<3}  {white:>5}  "
                    f"{_verdict(ch.independent):>16}"
                )
        lines.append("")
    lines.append(
        "fit [%] = 100 (1 - |y - y_hat| / |y - mean(y)|); residual tests at 99 % "
        f"(lags up to {result.options.max_lag} samples)"
    )
    return "\n".join(lines)
