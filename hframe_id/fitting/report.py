"""The fit report: a markdown file with plots comparing the fit with the thesis (and truth).

Sections: status; the model-mismatch statement when the fit weighed the channels by noise
levels estimated from its residuals; parameter table against the thesis's Table 4.2
(hframe-8) or Table 2.3 (one-axis), with a truth column when the recordings carry their
plant's parameters (sim rig), through the section-4.1 reduction for an hframe-20 plant
fitted with hframe-8; parameters the data do not identify and which experiments would;
leave-one-recording-out cross-validation; measured vs simulated signals (fitted and thesis
parameters) and residuals for every experiment; the correlation matrix (values in the cells)
with a sentence per group of strongly correlated parameters.

The sections computed from the fit alone (parameter table, not identified, correlated groups,
cross-validation) are written in :mod:`hframe_id.fitting.report_tables`; this module adds what
needs the recordings, simulations or figures, and writes the file.

The figures (``report_figures``: matplotlib imported inside the plotting functions, so
importing this module sets no backend and no global state) are drawn here or, given a
``ProcessDrawer``, in worker processes while the report is written.
Plots are drawn into a hidden temporary folder that is renamed into place at the end, so a
failure leaves neither plots nor report behind; ``plots=False`` writes the report alone.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hframe_id.atomic import replace_atomically, staged_directory
from hframe_id.figure_drawers import InlineDrawer, ProcessDrawer
from hframe_id.fitting.experiment import applied_inputs
from hframe_id.fitting.known_points import KnownPointsReport
from hframe_id.fitting.multistart import StartOutcome, reached_best
from hframe_id.fitting.noise_rounds import NoiseSettling
from hframe_id.fitting.report_figures import (
    ExperimentSignals,
    plot_correlation,
    plot_experiment,
    shown_in,
)
from hframe_id.fitting.report_tables import (
    correlation_lines,
    cross_validation_lines,
    information_lines,
    markdown_table,
    not_identified_lines,
    parameter_table,
)
from hframe_id.fitting.result import FitResult
from hframe_id.models import build_model, declaration
from hframe_id.parameters import ParameterSet, load_parameter_file
from hframe_id.parameters.reduce import reduce_to_hframe8
from hframe_id.recordings.recording import Recording
from hframe_id.simulation.open_loop import default_substeps, outputs_of, simulate
from hframe_id.validation.cross_validation import LeaveOneOutTable
from hframe_id.validation.replay import channels


@dataclass(frozen=True)
class Figures:
    """Where the report's figures go: drawn by ``drawer`` into ``folder``, linked from the
    report as ``link``/name."""

    folder: Path
    link: str
    drawer: InlineDrawer | ProcessDrawer

    def add(self, caption: str, name: str, function, *args) -> list[str]:
        """Have ``function(*args, folder / name)`` drawn; the report's lines linking it."""
        self.drawer.draw(function, *args, self.folder / name)
        return [f"![{caption}]({self.link}/{name})", ""]


def model_reference(variant: str) -> tuple[ParameterSet | None, str]:
    """The declared reference set a fit of ``variant`` is compared with, and its source
    (the thesis's table for its variants); (None, "") if the model declares none."""
    declared = declaration(variant)
    if declared.reference_file is None:
        return None, ""
    return load_parameter_file(declared.reference_file), declared.reference_label


def common_truth(recordings: list[Recording]) -> ParameterSet | None:
    """The plant parameters if every recording carries the same ones."""
    truths = [rec.truth for rec in recordings]
    if any(t is None for t in truths):
        return None
    first = truths[0]
    same = all(t.variant == first.variant and t.values == first.values for t in truths)
    return first if same else None


def comparable_truth(
    recordings: list[Recording], variant: str
) -> tuple[ParameterSet | None, str, str]:
    """The recordings' plant parameters as a set of the fitted ``variant``.

    Returns
    -------
    truth : the plant's parameters (an hframe-20 plant fitted with hframe-8: its section-4.1
        reduction), or None when the recordings carry no common plant or it has no
        counterpart in ``variant``.
    label : the truth column's heading.
    note : a sentence for the report on what the truth column is, or why there is none.
    """
    truth = common_truth(recordings)
    if truth is None:
        return None, "", ""
    if truth.variant == variant:
        return truth, "truth", "and the plant's true parameters, which the recordings carry."
    if truth.variant == "hframe-20" and variant in ("hframe-8", declaration("hframe-8").nests_in):
        return (
            reduce_to_hframe8(truth),
            "truth (section-4.1 reduction of the plant)",
            "and the section-4.1 reduction (eq. 4.2-4.8) of the hframe-20 plant that made the "
            "recordings: the hframe-8 parameters closest to that plant, not an exact truth.",
        )
    return (
        None,
        "",
        f"No truth column: the recordings' plant parameters are of the {truth.variant} "
        f"model, which has no reduction to the fitted {variant} model.",
    )


def output_units(variant: str) -> dict[str, str]:
    """SI unit of each output of ``variant``'s model (``"rad"`` or ``"m"``)."""
    return {s.name: s.unit for s in build_model(variant).outputs}


def mismatch_statement(result: FitResult) -> str | None:
    """A plain sentence saying that the model does not follow the data at the sensors' noise
    level, or None when the fit weighed its channels by the sensors' noise or, with noise
    levels estimated (a first solve that stalled above it), still ended within
    ``StrategySettings.mismatch_rms`` sensor std on every channel."""
    noise = result.diagnostics.noise
    if noise is None or noise.method != "estimated":
        return None
    ratios = [c.residual_rms_sensor_std for c in noise.channels.values()]
    if max(ratios) <= result.options.strategy.mismatch_rms:
        return None
    span = f"{ratios[0]:.3g}" if len(ratios) == 1 else f"{min(ratios):.3g} to {max(ratios):.3g}"
    return (
        "The model does not follow the data at the sensors' noise level "
        f"(residual rms {span} x the sensor std, per channel below). The channels were "
        "weighted by noise levels estimated from the residuals "
        f"({noise.rounds} round(s)) instead of the sensor specifications; the residuals "
        "are model error more than noise."
        + _settling_text(noise.settling)
        + _best_known_text(result.diagnostics.known_points)
        + _portfolio_text(result.diagnostics.starts)
    )


def _portfolio_text(outcomes: tuple[StartOutcome, ...]) -> str:
    """How many starts of a multistart portfolio reached this optimum (more evidence that it
    is the best the model can do); empty without a portfolio."""
    if not outcomes:
        return ""
    return (
        f" {reached_best(outcomes)} of {len(outcomes)} starts of a multistart portfolio "
        "reached this optimum."
    )


def _best_known_text(report: KnownPointsReport | None) -> str:
    """The evidence that the mismatch is the model's, not a poor optimum's: the written
    parameters simulate the training records better than every point the fit knows
    (``fitting.known_points``); empty where they were not compared."""
    if report is None:
        return ""
    others = list(report.points)
    return (
        f" Its parameters simulate the training records better than the {len(others)} other "
        f"point(s) it knows ({', '.join(others)})."
    )


def _settling_text(settling: NoiseSettling | None) -> str:
    """A sentence for noise levels that had not reached their fixed point (empty if they
    had, or were not estimated)."""
    if settling is None or settling.settled:
        return ""
    return (
        " The noise levels had not settled when the rounds ended: the residual rms differs "
        f"from the weights by up to {100 * math.expm1(settling.change):.0f} % on a "
        "channel, so the weighting between channels is approximate."
    )


def mismatch_rows(result: FitResult) -> list[tuple[str, ...]]:
    """Header and one row per channel: sensor std, estimated noise std, residual rms, all in
    display units (rad, mm), and the residual rms in sensor std."""
    units = output_units(result.variant)
    rows = [
        (
            "channel",
            "sensor std",
            "estimated noise std",
            "residual rms",
            "residual rms [sensor std]",
        )
    ]
    for name, channel in result.diagnostics.noise.channels.items():
        scale, unit = shown_in(units[name])
        levels = (channel.sensor_std, channel.weight_std, channel.residual_rms)
        rows.append(
            (
                name,
                *(f"{scale * level:.3g} {unit}" for level in levels),
                f"{channel.residual_rms_sensor_std:.3g}",
            )
        )
    return rows


def recording_level_rows(result: FitResult) -> list[tuple[str, ...]]:
    """Header and one row per recording: the noise std the fit weighed each channel of that
    recording with (display units), or no rows if every recording was weighed alike."""
    channels = result.diagnostics.noise.channels
    if not any(c.differs_by_recording for c in channels.values()):
        return []
    units = output_units(result.variant)
    shown = {name: shown_in(units[name]) for name in channels}
    rows = [("recording", *(f"{name} std" for name in channels))]
    for k, recording in enumerate(result.experiment_names):
        rows.append(
            (
                recording,
                *(
                    f"{shown[name][0] * c.recording_std[k]:.3g} {shown[name][1]}"
                    for name, c in channels.items()
                ),
            )
        )
    return rows


def simulated_outputs(
    sets: list[ParameterSet | None], rec: Recording, x0: np.ndarray
) -> list[np.ndarray | None]:
    """(N, n_y) outputs of each parameter set (None: None) driven by the recording's applied
    inputs from ``x0``, all with the same RK4 substeps (the most any set needs), so that one
    integrator is built for all of them (a build costs 37 ms, as much as a simulation)."""
    model = build_model(next(ps for ps in sets if ps is not None).variant)
    vectors = [None if ps is None else model.parameter_vector(ps.values) for ps in sets]
    substeps = max(
        default_substeps(model, p, rec.sample_period_s) for p in vectors if p is not None
    )
    inputs = applied_inputs(rec)
    outputs = []
    for p in vectors:
        if p is None:
            outputs.append(None)
            continue
        states = simulate(model, p, inputs, rec.sample_period_s, x0=x0, n_substeps=substeps)
        outputs.append(outputs_of(model, states[:-1], inputs, p))
    return outputs


def _correlation_lines(result: FitResult, figures: Figures | None) -> list[str]:
    lines = ["## Correlation", ""]
    if figures is not None:
        matrix = np.asarray(result.correlation)
        names = tuple(result.free_names)
        lines += figures.add("correlation", "correlation.png", plot_correlation, matrix, names)
    return [*lines, *correlation_lines(result), ""]


def incomplete_recordings(recordings: list[Recording]) -> list[str]:
    """A sentence per recording that is not its complete run (salvaged, aborted, samples
    lost), saying how many of the planned samples were fitted."""
    from hframe_id.recordings.completeness import completeness

    return [
        f"{rec.name()}: {statement}"
        for rec in recordings
        if (statement := completeness(rec).statement())
    ]


def _status_lines(result: FitResult, recordings: list[Recording], parameter_file) -> list[str]:
    status = "success" if result.success else "**FAILED**"
    incomplete = [f"- incomplete recording: {line}" for line in incomplete_recordings(recordings)]
    return [
        f"- status: {status} (solver: {result.message})",
        f"- model: {result.variant}; {len(recordings)} experiment(s): "
        + ", ".join(rec.name() for rec in recordings),
        *incomplete,
        f"- cost {result.cost:.6g} (residual rms {result.residual_rms:.3g} x the noise "
        f"levels weighed with), {result.iterations} iterations, "
        f"{result.wall_time_s:.2f} s wall time",
        f"- parameter file: `{parameter_file}`"
        if parameter_file
        else "- parameter file: none written (the fit failed; do not use these values)",
        f"- uncertainty: {result.options.uncertainty} method, "
        f"{round(100 * result.options.confidence)} % intervals",
        *(f"- {line}" for line in result.search_statements if line),
        "",
    ]


def _signal_lines(
    result: FitResult,
    recordings: list[Recording],
    thesis: ParameterSet | None,
    label: str,
    figures: Figures | None,
) -> list[str]:
    """Per experiment: rms residuals and a figure (None: no figures). A channel with a
    sensor latency of d samples is shown as the fit compared it: advanced by d samples
    (``validation.replay.channels``), so that these are the residuals ``validate`` shows."""
    units = output_units(result.variant)
    model = build_model(result.variant)
    latency = result.options.latency_samples
    lines = ["## Measured and simulated signals", ""]
    x0s = result.initial_states
    for i, rec in enumerate(recordings):
        x0 = x0s[i] if x0s is not None else None
        fitted, reference = simulated_outputs([result.parameters, thesis], rec, x0)
        data = channels(model, rec, latency)
        rms = []
        for j, name in enumerate(data.names):
            valid = data.valid[:, j]
            scale, unit = shown_in(units[name])
            value = np.sqrt(np.mean((data.measured[valid, j] - fitted[valid, j]) ** 2))
            delay = f" (sensor {latency[name]} samples late)" if latency.get(name) else ""
            rms.append(f"{name} {scale * value:.3g} {unit}{delay}")
        lines += [f"### {rec.name()}", "", f"RMS residual: {', '.join(rms)}", ""]
        if figures is not None:
            signals = ExperimentSignals(
                time_s=rec.time_s,
                names=data.names,
                units=tuple(units[name] for name in data.names),
                measured=data.measured,
                fitted=fitted,
                reference=reference,
                title=rec.name(),
            )
            png = f"{Path(rec.name()).stem}.png"
            lines += figures.add(rec.name(), png, plot_experiment, signals, label)
    return lines


def _report_lines(
    result: FitResult,
    recordings: list[Recording],
    fit_id: str,
    parameter_file: Path | None,
    cross_validation: LeaveOneOutTable | None,
    figures: Figures | None,
) -> list[str]:
    # The correlation map first: it needs no simulation, so a worker draws it meanwhile.
    correlation = _correlation_lines(result, figures) if len(result.free_names) > 1 else []
    thesis, label = model_reference(result.variant)
    truth, truth_label, truth_note = comparable_truth(recordings, result.variant)
    lines = [f"# Fit {fit_id}", "", *_status_lines(result, recordings, parameter_file)]
    statement = mismatch_statement(result)
    if statement:
        lines += ["## Model mismatch", "", statement, "", *markdown_table(mismatch_rows(result))]
        lines.append("")
        per_recording = recording_level_rows(result)
        if per_recording:
            lines += [
                "Each recording's residuals were weighed by their own noise level (model "
                "error differs between recordings):",
                "",
                *markdown_table(per_recording),
                "",
            ]
    intro = f"Fitted values against the model's reference set ({label})"
    if truth:
        intro += f" {truth_note}"
    else:
        intro += "." + (f" {truth_note}" if truth_note else "")
    if result.has_jackknife:
        intro += (
            " Two 95 % intervals: the fit's (noise, robust to correlated residuals, with any "
            "held parameter's prior) and the experiments' (delete-one-recording jackknife, "
            "Student's t with n - 1 degrees of freedom for n recordings), which holds model "
            "error that differs between experiments. Under model mismatch read the wider one."
        )
    held = result.held_statement()
    lines += [
        "## Parameters",
        "",
        intro,
        "",
        *parameter_table(result, thesis, label, truth, truth_label),
        "",
        *([held, ""] if held else []),
        *not_identified_lines(result),
        *information_lines(result),
    ]
    if cross_validation is not None:
        lines += cross_validation_lines(result, cross_validation)
    lines += _signal_lines(result, recordings, thesis, label, figures)
    return lines + correlation


def write_report(
    result: FitResult,
    recordings: list[Recording],
    fit_id: str,
    parameter_file: Path | None,
    out_dir: Path,
    cross_validation: LeaveOneOutTable | None = None,
    plots: bool = True,
    drawer: InlineDrawer | ProcessDrawer | None = None,
) -> Path:
    """Write ``<out_dir>/<fit id>-report.md`` and its plots in ``<fit id>-plots/``.

    Parameters
    ----------
    result : the fit.
    recordings : the recordings fitted, in the fit's order.
    fit_id : the fit's id (``output.write_parameter_file``); names the report and plots.
    parameter_file : the fit's parameter file, or None when none was written.
    out_dir : an existing folder.
    cross_validation : the leave-one-recording-out table, if computed.
    plots : draw the plots (False: the report alone, without figures).
    drawer : where the figures are drawn (default: here, one after the other).

    Returns
    -------
    The report's path. The plots are drawn into a hidden temporary folder renamed to
    ``<fit id>-plots`` once all are drawn; on any exception neither plots nor report is left.
    """
    if not plots:
        lines = _report_lines(result, recordings, fit_id, parameter_file, cross_validation, None)
        return replace_atomically(out_dir / f"{fit_id}-report.md", "\n".join(lines) + "\n")
    plot_dir = out_dir / f"{fit_id}-plots"
    drawer = drawer or InlineDrawer()
    with staged_directory(plot_dir) as staging:
        figures = Figures(staging, plot_dir.name, drawer)
        try:
            lines = _report_lines(
                result, recordings, fit_id, parameter_file, cross_validation, figures
            )
        except BaseException:
            drawer.discard()
            raise
        drawer.finish()
    try:
        return replace_atomically(out_dir / f"{fit_id}-report.md", "\n".join(lines) + "\n")
    except BaseException:
        shutil.rmtree(plot_dir, ignore_errors=True)
        raise
