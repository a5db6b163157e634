"""The fit report: a markdown file with plots comparing the fit with the thesis (and truth).

Sections: status; the model-mismatch statement when the fit weighed the channels by noise
levels estimated from its residuals; parameter table against the thesis's Table 4.2
(hframe-8) or Table 2.3 (one-axis), with a truth column when the recordings carry their
plant's parameters (sim rig), through the section-4.1 reduction for an hframe-20 plant
fitted with hframe-8; parameters the data do not identify and which experiments would;
leave-one-recording-out cross-validation; measured vs simulated signals (fitted and thesis
parameters) and residuals for every experiment; the correlation matrix (values in the cells)
with a sentence per group of strongly correlated parameters.

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
from hframe_id.fitting.multistart import reached_best
from hframe_id.fitting.noise_rounds import MISMATCH_RMS
from hframe_id.fitting.problem import applied_inputs
from hframe_id.fitting.report_figures import (
    ExperimentSignals,
    plot_correlation,
    plot_experiment,
    shown_in,
)
from hframe_id.fitting.result import FitResult
from hframe_id.models import build_model, declaration
from hframe_id.parameters import ParameterSet, load_parameter_file
from hframe_id.parameters.reduce import reduce_to_hframe8
from hframe_id.recordings.recording import Recording
from hframe_id.simulation.open_loop import default_substeps, outputs_of, simulate
from hframe_id.validation.cross_validation import LeaveOneOutTable


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
    if truth.variant == "hframe-20" and variant == "hframe-8":
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


def _fmt(value: float) -> str:
    return f"{value:.5g}"


def _relative_difference(value: float, reference: float, digits: int) -> str:
    """``value`` against ``reference`` in percent, or the absolute difference where the
    reference is 0 (a linear table's Coulomb friction), which has no relative one."""
    if reference == 0:
        return f"{_fmt(value - reference)} (reference 0)"
    return f"{100 * (value / reference - 1):+.{digits}f} %"


def output_units(variant: str) -> dict[str, str]:
    """SI unit of each output of ``variant``'s model (``"rad"`` or ``"m"``)."""
    return {s.name: s.unit for s in build_model(variant).outputs}


def mismatch_statement(result: FitResult) -> str | None:
    """A plain sentence saying that the model does not follow the data at the sensors' noise
    level, or None when the fit weighed its channels by the sensors' noise or, with noise
    levels estimated (a first solve that stalled above it), still ended within
    ``MISMATCH_RMS`` sensor std on every channel."""
    noise = result.diagnostics.get("noise")
    if noise is None or noise["method"] != "estimated":
        return None
    ratios = [c["residual_rms_sensor_std"] for c in noise["channels"].values()]
    if max(ratios) <= MISMATCH_RMS:
        return None
    span = f"{ratios[0]:.3g}" if len(ratios) == 1 else f"{min(ratios):.3g} to {max(ratios):.3g}"
    return (
        "The model does not follow the data at the sensors' noise level "
        f"(residual rms {span} x the sensor std, per channel below). The channels were "
        "weighted by noise levels estimated from the residuals "
        f"({noise['rounds']} round(s)) instead of the sensor specifications; the residuals "
        "are model error more than noise."
        + _settling_text(noise.get("settling"))
        + _best_known_text(result.diagnostics.get("known_points"))
        + _portfolio_text(result.diagnostics.get("starts"))
    )


def _portfolio_text(outcomes) -> str:
    """How many starts of a multistart portfolio reached this optimum (more evidence that it
    is the best the model can do); empty without a portfolio."""
    if not outcomes:
        return ""
    return (
        f" {reached_best(outcomes)} of {len(outcomes)} starts of a multistart portfolio "
        "reached this optimum."
    )


def _best_known_text(points: dict | None) -> str:
    """The evidence that the mismatch is the model's, not a poor optimum's: the written
    parameters simulate the training records better than every point the fit knows
    (``fitting.known_points``); empty where they were not compared."""
    if not points:
        return ""
    others = [label for label in points if label != "fit" and not label.startswith("fit ")]
    return (
        f" Its parameters simulate the training records better than the {len(others)} other "
        f"point(s) it knows ({', '.join(others)})."
    )


def _settling_text(settling: dict | None) -> str:
    """A sentence for noise levels that had not reached their fixed point (empty if they
    had, or for reports written before this was recorded)."""
    if settling is None or settling["settled"]:
        return ""
    return (
        " The noise levels had not settled when the rounds ended: the residual rms differs "
        f"from the weights by up to {100 * math.expm1(settling['change']):.0f} % on a "
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
    for name, channel in result.diagnostics["noise"]["channels"].items():
        scale, unit = shown_in(units[name])
        rows.append(
            (
                name,
                *(
                    f"{scale * channel[key]:.3g} {unit}"
                    for key in ("sensor_std", "weight_std", "residual_rms")
                ),
                f"{channel['residual_rms_sensor_std']:.3g}",
            )
        )
    return rows


def markdown_table(rows: list[tuple[str, ...]]) -> list[str]:
    """Markdown lines of a table whose first row is the header."""
    head, *body = rows
    return [
        "| " + " | ".join(head) + " |",
        "|" + " --- |" * len(head),
        *("| " + " | ".join(row) + " |" for row in body),
    ]


def parameter_table(
    result: FitResult,
    thesis: ParameterSet | None,
    label: str,
    truth: ParameterSet | None,
    truth_label: str = "truth",
) -> list[str]:
    """Markdown rows of the free parameters: reference value (``thesis``, labelled
    ``label``), fitted value, interval, the experiment-level jackknife's interval (after a
    cross-validation), difference from the reference [%], identifiability and, with
    ``truth``, the error against it [%]; units in the parameter names."""
    header = (
        "parameter",
        f"reference ({label})",
        "fitted",
        "95 % interval",
        "vs reference",
        "identified",
    )
    jackknife = result.has_jackknife
    if jackknife:
        header = header[:4] + ("95 % interval, experiments (jackknife)",) + header[4:]
    if truth:
        header += (truth_label, "error vs truth")
    rows = [header]
    for est in result.estimates.values():
        if not est.free:
            continue
        ref = thesis.values.get(est.name) if thesis else None
        diff = _relative_difference(est.estimate, ref, 2) if ref is not None else "n/a"
        if not result.success:
            status = "not assessed (fit failed)"
        elif est.open_ended:
            status = f"not bounded {est.open_ended} by the data (interval open there)"
        elif est.at_bound:
            status = "**at bound** (the box fixes it; interval ends there)"
        elif est.identified:
            status = "yes"
        elif est.name in result.not_identified:
            status = "**no** (held at initial)"
        else:
            status = "poorly determined (kept at estimate)"
        if est.name in result.prior_names:
            status += ", with a prior"
        cells = (
            est.key,
            _fmt(ref) if ref is not None else "n/a",
            _fmt(est.estimate),
            f"[{_fmt(est.ci95[0])}, {_fmt(est.ci95[1])}]",
            diff,
            status,
        )
        if jackknife:
            ci = est.jackknife_ci95
            cells = cells[:4] + (f"[{_fmt(ci[0])}, {_fmt(ci[1])}]" if ci else "n/a",) + cells[4:]
        if truth:
            t = truth.values[est.name]
            cells += (_fmt(t), _relative_difference(est.estimate, t, 3))
        rows.append(cells)
    return markdown_table(rows)


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


#: |correlation| from which the report calls two free parameters strongly correlated: their
#: estimates move together, and the data fix a combination better than each one.
STRONG_CORRELATION = 0.9


def correlated_groups(result: FitResult) -> list[tuple[tuple[str, ...], float]]:
    """Groups of free parameters joined by |correlation| >= STRONG_CORRELATION (connected
    components), each with its largest |correlation|, strongest first."""
    names = list(result.free_names)
    strong = np.abs(np.asarray(result.correlation)) >= STRONG_CORRELATION
    seen: set[int] = set()
    groups = []
    for start in range(len(names)):
        if start in seen:
            continue
        members, todo = [], [start]
        while todo:
            k = todo.pop()
            if k in seen:
                continue
            seen.add(k)
            members.append(k)
            todo += [j for j in np.flatnonzero(strong[k]) if j not in seen]
        if len(members) > 1:
            members.sort()
            block = np.abs(np.asarray(result.correlation)[np.ix_(members, members)])
            largest = float(np.max(block - np.eye(len(members))))
            groups.append((tuple(names[k] for k in members), largest))
    return sorted(groups, key=lambda group: -group[1])


def correlation_lines(result: FitResult) -> list[str]:
    """What the data cannot separate: a line per strongly correlated group, with the
    experiments that would separate it where the fitter's design advice names any."""
    groups = correlated_groups(result)
    if not groups:
        return [f"No two free parameters have |r| >= {STRONG_CORRELATION}."]
    lines = [
        f"Strongly correlated free parameters (|r| >= {STRONG_CORRELATION}): within each group, "
        "these data determine a combination of the parameters much better than each one. "
        "The intervals above include this; change one only together with the others (the "
        "parameter file's uncertainty section holds the correlation matrix).",
        "",
    ]
    advised = False
    for group, largest in groups:
        keys = ", ".join(result.estimates[name].key for name in group)
        advice = sorted({d for name in group for d in result.estimates[name].identified_by})
        advised |= bool(advice)
        tail = f"; experiments that would separate them: {', '.join(advice)}" if advice else ""
        lines.append(f"- {keys} (|r| up to {largest:.3f}){tail}")
    if not advised:
        lines += [
            "",
            "To separate a group, add an experiment that excites its members differently "
            "(another amplitude, direction or frequency content); the fitter proposes standard "
            "experiments only for parameters it cannot identify.",
        ]
    return lines


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


def _not_identified_lines(result: FitResult) -> list[str]:
    """Free parameters the data do not determine: held at their initial values, stopped by
    a bound of the box, or (under model mismatch) kept at their estimates."""
    weak = [est for est in result.estimates.values() if est.free and not est.identified]
    if not result.success or not weak:
        return []
    lines = ["## Not identified, at a bound or poorly determined", ""]
    for est in weak:
        if est.open_ended:
            fate = (
                f"on the box at {_fmt(est.estimate)}, and the data do not bound it "
                f"{est.open_ended}: moved back towards the start, the fit is no worse "
                "(see the verdict); any value beyond its interval's finite end fits as well."
            )
        elif est.at_bound:
            fate = (
                f"stopped at a bound of the box, {_fmt(est.estimate)}: the data push it "
                "further, the box fixes it (--bounds widens the box)."
            )
        elif est.name in result.not_identified:
            would = (
                ", ".join(est.identified_by)
                if est.identified_by
                else "none of the standard step experiments alone"
            )
            fate = (
                f"held at its initial value {_fmt(est.initial)}. Experiments that would "
                f"identify it: {would}."
            )
        else:
            fate = f"kept at its estimate {_fmt(est.estimate)} (poorly determined)."
        lines.append(
            f"- {est.key}: relative standard error {100 * est.relative_std:.3g} % "
            f"(collinearity {est.collinearity:.3g}); {fate}"
        )
    return [*lines, ""]


def _cross_validation_lines(result: FitResult, table: LeaveOneOutTable) -> list[str]:
    return [
        "## Leave-one-recording-out cross-validation",
        "",
        "Each recording simulated with the parameters fitted to the others (same options and "
        "start): simulation fit [%] = 100 (1 - |y - y_hat| / |y - mean(y)|) per channel, and "
        "the free parameters' spread across the converged folds (SI), with the "
        "experiment-level jackknife standard error.",
        "",
        table.markdown(),
        "",
        *_jackknife_sentence(result, table),
    ]


#: Jackknife std over the fit's std error above which the report says the intervals are
#: too narrow: 2 (a ratio of two noisy standard errors, with few experiments, scatters by
#: tens of percent even when both estimate the same spread).
JACKKNIFE_RATIO = 2.0


def _jackknife_sentence(result: FitResult, table: LeaveOneOutTable) -> list[str]:
    """Which parameters move across experiments by more than their intervals allow."""
    wider = []
    for s in table.spread:
        est = result.estimates.get(s.name)
        if est and est.std_error > 0 and s.jackknife_std > JACKKNIFE_RATIO * est.std_error:
            wider.append(f"{s.name} ({s.jackknife_std / est.std_error:.3g}x)")
    if not wider:
        return []
    return [
        "The fit's intervals account for noise only. Across experiments, these parameters "
        "move by more than twice their standard error (jackknife std / fit std): "
        f"{', '.join(wider)}. Model error that differs between experiments is larger than the "
        "intervals say; read the jackknife interval of the parameter table as theirs.",
        "",
    ]


def _signal_lines(
    result: FitResult,
    recordings: list[Recording],
    thesis: ParameterSet | None,
    label: str,
    figures: Figures | None,
) -> list[str]:
    """Per experiment: rms residuals and a figure (None: no figures)."""
    units = output_units(result.variant)
    lines = ["## Measured and simulated signals", ""]
    x0s = result.initial_states
    for i, rec in enumerate(recordings):
        x0 = x0s[i] if x0s is not None else None
        fitted, reference = simulated_outputs([result.parameters, thesis], rec, x0)
        rms = []
        for j, name in enumerate(rec.output_names):
            valid = rec.valid[:, j]
            scale, unit = shown_in(units[name])
            value = np.sqrt(np.mean((rec.outputs[valid, j] - fitted[valid, j]) ** 2))
            rms.append(f"{name} {scale * value:.3g} {unit}")
        lines += [f"### {rec.name()}", "", f"RMS residual: {', '.join(rms)}", ""]
        if figures is not None:
            signals = ExperimentSignals(
                time_s=rec.time_s,
                names=tuple(rec.output_names),
                units=tuple(units[name] for name in rec.output_names),
                measured=np.where(rec.valid, rec.outputs, np.nan),
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
        *_not_identified_lines(result),
    ]
    if cross_validation is not None:
        lines += _cross_validation_lines(result, cross_validation)
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
