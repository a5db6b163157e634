"""``validate``'s results as a versioned JSON document and as a plain-text table
(docs/validation.md, "JSON output")."""

from __future__ import annotations

import math
from typing import Any

from hframe_id import __version__
from hframe_id.validation.closed_loop import QUANTITIES, ClosedLoopScore
from hframe_id.validation.compare import ChannelResult, RunResult, ValidationResult
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


def _closed_loop(score: ClosedLoopScore | None) -> dict[str, Any] | None:
    if score is None:
        return None
    run, controller = score.run, score.controller
    errors = score.relative_error_percent
    return {
        "controller": controller.name,
        "controller_file": str(controller.controller_file) if controller.controller_file else None,
        "sample_period_s": run.sample_period_s,
        "friction": run.friction.model,
        "substeps": run.n_substeps,
        "disturbances": list(run.disturbances),
        "channels": list(score.channels),
        "samples": score.samples,
        "stable": run.stable,
        "diverged_at_s": run.diverged_at_s,
        "relative_error_percent": None
        if errors is None
        else {q: _number(errors[q]) for q in QUANTITIES},
        "unavailable": score.unavailable,
    }


def _scores(run: RunResult, init_samples: int) -> dict[str, Any]:
    """The scores the literature uses, as the JSON document holds them per parameter file."""
    inverse = run.inverse_model
    return {
        "open_loop": {
            "init_samples": init_samples,
            "rmse": {name: _number(value) for name, value in run.open_loop_rmse.items()},
        },
        "inverse_model": {
            "force_error_percent": _number(inverse.force_error_percent),
            "decimation": inverse.decimation,
            "samples": inverse.samples,
            "friction": inverse.friction,
            "unavailable": inverse.unavailable,
        },
        "closed_loop": _closed_loop(run.closed_loop),
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
            "init_samples": options.init_samples,
            "friction": options.friction,
        },
        "parameter_files": [
            {
                "label": label,
                "path": str(params.path) if params.path else None,
                "model": params.variant,
                "title": params.title,
                "latency_samples": latency,
            }
            for label, params, latency in zip(
                result.labels, result.parameter_sets, result.latencies, strict=True
            )
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
                        **_scores(run, options.init_samples),
                    }
                    for run in entry.runs
                ],
            }
            for entry in result.recordings
        ],
    }


def _digits(value: float | None, width: int) -> str:
    """Five significant digits: enough to tell parameter sets apart."""
    text = "-" if value is None or not math.isfinite(value) else f"{value:#.5g}"
    return f"{text:>{width}}"


def _scores_text(entry, labels: tuple[str, ...], options) -> list[str]:
    """The literature's scores of every parameter set on one recording."""
    width = max(len(label) for label in labels)
    runs = entry.runs
    factor = runs[0].inverse_model.decimation
    lines = [
        f"  {'parameters':<{width}}  inverse-model force error [%]  "
        f"open-loop RMSE after {options.init_samples} samples"
    ]
    for run in runs:
        rmse = ", ".join(
            f"{name} {_digits(value, 0)} {channel.unit}"
            for (name, value), channel in zip(run.open_loop_rmse.items(), run.channels, strict=True)
        )
        lines.append(
            f"  {run.label:<{width}}  {_digits(run.inverse_model.force_error_percent, 29)}  {rmse}"
        )
    reasons = {r.inverse_model.unavailable for r in runs} - {None}
    lines.append(
        f"  inverse model: {options.friction} friction, decimated {factor}x"
        + (f"; not available: {'; '.join(sorted(reasons))}" if reasons else "")
    )
    closed = [run.closed_loop for run in runs if run.closed_loop is not None]
    if not closed:
        return lines
    first = closed[0]
    controller, loop = first.controller, first.run
    where = f" ({controller.controller_file.name})" if controller.controller_file else ""
    added = ", ".join(loop.disturbances) or "none in the recording"
    lines += [
        f"  closed loop with {controller.name}{where}: T = {1e3 * loop.sample_period_s:.9g} ms, "
        f"{loop.friction.model} friction, {loop.n_substeps} RK4 substeps, disturbances: {added}",
        f"  {'parameters':<{width}}  " + "  ".join(f"{q + ' [%]':>16}" for q in QUANTITIES),
    ]
    for run in runs:
        score = run.closed_loop
        if score.relative_error_percent is None:
            lines.append(
                f"  {run.label:<{width}}  unstable closed loop: the simulation diverged at "
                f"t = {score.run.diverged_at_s:.4g} s"
            )
            continue
        values = "  ".join(_digits(score.relative_error_percent[q], 16) for q in QUANTITIES)
        lines.append(f"  {run.label:<{width}}  {values}")
    reasons = {f"{q}: {why}" for s in closed for q, why in s.unavailable.items()}
    if reasons:
        lines.append(f"  not available: {'; '.join(sorted(reasons))}")
    return lines


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
        lines += _scores_text(entry, result.labels, result.options)
        lines.append("")
    for label, latency in zip(result.labels, result.latencies, strict=True):
        delays = ", ".join(f"{name} {d}" for name, d in latency.items() if d)
        if delays:
            lines.append(
                f"{label}: sensor latency as fitted, {delays} sample(s): each such channel "
                "is compared with the simulation that many samples earlier"
            )
    lines.append(
        "fit [%] = 100 (1 - |y - y_hat| / |y - mean(y)|); residual tests at 99 % "
        f"(lags up to {result.options.max_lag} samples)"
    )
    lines.append(
        "inverse-model and closed-loop errors [%] = 100 |y - y_hat| / |y|, computed as the EMPS "
        "benchmark's scripts do (docs/validation.md)"
    )
    return "\n".join(lines)
