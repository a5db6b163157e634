"""The fit report: a markdown file with plots comparing the fit with the thesis (and truth).

Sections: status; parameter table against the thesis's Table 4.2 (hframe-8) or Table 2.3
(one-axis), with a truth column when the recordings carry their plant's parameters (sim rig);
parameters the data do not identify and which experiments would; measured vs simulated signals
(fitted and thesis parameters) and residuals for every experiment; the correlation matrix.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from hframe_id.atomic import replace_atomically  # noqa: E402
from hframe_id.fitting.fit import FitResult  # noqa: E402
from hframe_id.fitting.problem import applied_inputs  # noqa: E402
from hframe_id.models import build_model  # noqa: E402
from hframe_id.parameters import ParameterSet, load_parameter_file  # noqa: E402
from hframe_id.recordings.recording import Recording  # noqa: E402
from hframe_id.simulation.open_loop import simulate  # noqa: E402

MODELS_DIR = Path(__file__).resolve().parents[2] / "models"
#: The thesis's parameter set each variant's fit is compared with.
THESIS_REFERENCE = {
    "hframe-8": ("hframe-8-table4.2.yaml", "Table 4.1 + 4.2"),
    "one-axis": ("one-axis-table2.3.yaml", "Table 2.1 + 2.3"),
    "hframe-20": ("hframe-20-table3.1.yaml", "Table 3.1"),
}
#: Plot scale per output unit: show angles in rad, positions in mm.
_SCALE = {"rad": (1.0, "rad"), "m": (1e3, "mm")}
_RESIDUAL_SCALE = {"rad": (1e6, "urad"), "m": (1e6, "um")}


def thesis_reference(variant: str) -> tuple[ParameterSet | None, str]:
    name, label = THESIS_REFERENCE[variant]
    path = MODELS_DIR / name
    return (load_parameter_file(path) if path.exists() else None), label


def common_truth(recordings: list[Recording]) -> ParameterSet | None:
    """The plant parameters if every recording carries the same ones."""
    truths = [rec.truth for rec in recordings]
    if any(t is None for t in truths):
        return None
    first = truths[0].values
    return truths[0] if all(t.values == first for t in truths) else None


def _fmt(value: float) -> str:
    return f"{value:.5g}"


def parameter_table(
    result: FitResult, thesis: ParameterSet | None, label: str, truth: ParameterSet | None
) -> list[str]:
    header = [
        "parameter",
        f"thesis ({label})",
        "fitted",
        "95 % interval",
        "vs thesis",
        "identified",
    ]
    if truth:
        header += ["truth", "error vs truth"]
    rows = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    for est in result.estimates.values():
        if not est.free:
            continue
        ref = thesis.values.get(est.name) if thesis else None
        diff = f"{100 * (est.estimate / ref - 1):+.2f} %" if ref else "n/a"
        if not result.success:
            status = "not assessed (fit failed)"
        elif est.identified:
            status = "yes"
        else:
            status = "**no** (held at initial)"
        if est.at_bound:
            status += ", at bound"
        cells = [
            est.key,
            _fmt(ref) if ref is not None else "n/a",
            _fmt(est.estimate),
            f"[{_fmt(est.ci95[0])}, {_fmt(est.ci95[1])}]",
            diff,
            status,
        ]
        if truth:
            t = truth.values[est.name]
            cells += [_fmt(t), f"{100 * (est.estimate / t - 1):+.3f} %"]
        rows.append("| " + " | ".join(cells) + " |")
    return rows


def simulated_outputs(params: ParameterSet, rec: Recording, x0: np.ndarray) -> np.ndarray:
    """(N, n_y) outputs of ``params`` driven by the recording's applied inputs from ``x0``."""
    model = build_model(params.variant)
    states = simulate(
        model,
        model.parameter_vector(params.values),
        applied_inputs(rec),
        rec.sample_period_s,
        x0=x0,
    )[:-1]
    return np.array(model.output.map(states.shape[0])(states.T)).T


def plot_experiment(
    rec: Recording, fitted: np.ndarray, thesis: np.ndarray | None, label: str, path: Path
) -> None:
    model = build_model(rec.variant)
    units = [s.unit for s in model.outputs]
    n = len(rec.output_names)
    fig, axes = plt.subplots(2, n, figsize=(4.2 * n, 6), sharex=True, squeeze=False)
    t = rec.time_s
    for j, name in enumerate(rec.output_names):
        scale, unit = _SCALE[units[j]]
        rscale, runit = _RESIDUAL_SCALE[units[j]]
        valid = rec.valid[:, j]
        ax = axes[0, j]
        measured = np.where(valid, rec.outputs[:, j], np.nan)
        ax.plot(t, scale * measured, "k.", ms=1.5, label="measured (valid)")
        ax.plot(t, scale * fitted[:, j], "C0", lw=1.2, label="fitted")
        if thesis is not None:
            ax.plot(t, scale * thesis[:, j], "C3--", lw=1, label=f"thesis {label}")
        ax.set_title(f"{name} [{unit}]")
        ax.grid(alpha=0.3)
        res = axes[1, j]
        res.plot(t, rscale * (measured - fitted[:, j]), "C0", lw=0.8)
        res.set_ylabel(f"measured - fitted [{runit}]")
        res.set_xlabel("time [s]")
        res.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(rec.name())
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_correlation(result: FitResult, path: Path) -> None:
    names = list(result.free_names)
    fig, ax = plt.subplots(figsize=(0.45 * len(names) + 2.5, 0.45 * len(names) + 1.5))
    image = ax.imshow(result.correlation, cmap="RdBu_r", vmin=-1, vmax=1)
    ax.set_xticks(range(len(names)), names, rotation=90, fontsize=8)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    fig.colorbar(image, ax=ax, shrink=0.8, label="correlation")
    ax.set_title("Correlation of the free parameters")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_report(
    result: FitResult,
    recordings: list[Recording],
    fit_id: str,
    parameter_file: Path | None,
    out_dir: Path,
) -> Path:
    """Write ``<out_dir>/<fit id>-report.md`` and its plots in ``<fit id>-plots/``."""
    plots = out_dir / f"{fit_id}-plots"
    plots.mkdir(parents=True, exist_ok=True)
    thesis, label = thesis_reference(result.variant)
    truth = common_truth(recordings)
    lines = [f"# Fit {fit_id}", ""]
    status = "success" if result.success else "**FAILED**"
    lines += [
        f"- status: {status} (solver: {result.message})",
        f"- model: {result.variant}; {len(recordings)} experiment(s): "
        + ", ".join(rec.name() for rec in recordings),
        f"- cost {result.cost:.6g} (residual rms {result.residual_rms:.3g} x the noise "
        f"model), {result.iterations} iterations, "
        f"{result.wall_time_s:.2f} s wall time",
        f"- parameter file: `{parameter_file}`"
        if parameter_file
        else "- parameter file: none written (the fit failed; do not use these values)",
        f"- uncertainty: {result.options.uncertainty} method, "
        f"{round(100 * result.options.confidence)} % intervals",
        "",
        "## Parameters",
        "",
        f"Fitted values against the thesis ({label})"
        + (
            " and the plant's true parameters, which the recordings carry (sim rig)."
            if truth
            else "."
        ),
        "",
        *parameter_table(result, thesis, label, truth),
        "",
    ]
    held = [est for est in result.estimates.values() if est.free and not est.identified]
    if held:
        lines += ["## Not identified", ""]
        for est in held:
            would = (
                ", ".join(est.identified_by)
                if est.identified_by
                else "none of the standard step experiments alone"
            )
            lines.append(
                f"- {est.key}: relative standard error {100 * est.relative_std:.3g} % "
                f"(collinearity {est.collinearity:.3g}); held at its initial value "
                f"{_fmt(est.initial)}. Experiments that would identify it: {would}."
            )
        lines.append("")
    lines += ["## Measured and simulated signals", ""]
    x0s = result.initial_states
    for i, rec in enumerate(recordings):
        x0 = x0s[i] if x0s is not None else None
        fitted = simulated_outputs(result.parameters, rec, x0)
        reference = simulated_outputs(thesis, rec, x0) if thesis else None
        png = plots / f"{Path(rec.name()).stem}.png"
        plot_experiment(rec, fitted, reference, label, png)
        rms = [
            np.sqrt(np.nanmean((rec.outputs[rec.valid[:, j], j] - fitted[rec.valid[:, j], j]) ** 2))
            for j in range(len(rec.output_names))
        ]
        rms_text = ", ".join(
            f"{name} {value:.3g}" for name, value in zip(rec.output_names, rms, strict=True)
        )
        lines += [
            f"### {rec.name()}",
            "",
            f"RMS residual (SI): {rms_text}",
            "",
            f"![{rec.name()}]({plots.name}/{png.name})",
            "",
        ]
    if len(result.free_names) > 1:
        png = plots / "correlation.png"
        plot_correlation(result, png)
        lines += ["## Correlation", "", f"![correlation]({plots.name}/{png.name})", ""]
    path = out_dir / f"{fit_id}-report.md"
    return replace_atomically(path, "\n".join(lines))
