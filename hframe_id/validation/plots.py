"""Plots of a validation: ``compare`` (measured vs simulated, per channel, every parameter set)
and ``resid`` (residual autocorrelation and input cross-correlation with the 99 % band).

matplotlib is imported inside the functions (the Agg backend, no display), so importing this
module costs nothing and sets no global state.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from hframe_id.atomic import Staging
from hframe_id.validation.compare import RecordingResult, RunResult


def _figure(rows: int, cols: int, size: tuple[float, float]):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(figure)
    return figure, figure.subplots(rows, cols, squeeze=False)


def _png(figure) -> bytes:
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110)
    return buffer.getvalue()


def compare_png(entry: RecordingResult) -> bytes:
    """Measured and simulated outputs of one recording, one panel per channel, every
    parameter set, with its simulation fit [%] in the legend."""
    first = entry.runs[0].data
    time_s = entry.recording.time_s
    n = len(first.names)
    figure, axes = _figure(n, 1, (9.0, 2.3 * n + 0.6))
    for j, name in enumerate(first.names):
        ax = axes[j, 0]
        ax.plot(time_s, first.measured[:, j], color="black", lw=2.2, alpha=0.45, label="measured")
        for run in entry.runs:
            fit = run.channels[j].simulation_fit_percent
            ax.plot(time_s, run.simulated[:, j], lw=1.1, label=f"{run.label}: {fit:.1f} %")
        ax.set_ylabel(f"{name} [{first.units[j]}]")
        ax.legend(fontsize=8, loc="best")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    figure.suptitle(f"{entry.recording.name()}: measured vs simulated (fit = NRMSE %)")
    return _png(figure)


def resid_png(run: RunResult, recording_name: str) -> bytes:
    """Residual autocorrelation (lags 0..L) and cross-correlation with each input
    (lags -L..L) per channel, with the 99 % band (shaded)."""
    inputs = run.data.input_names
    n = len(run.channels)
    figure, axes = _figure(n, 1 + len(inputs), (4.0 * (1 + len(inputs)), 2.0 * n + 0.8))
    for i, ch in enumerate(run.channels):
        tests = [("autocorrelation", ch.autocorrelation)]
        tests += [(f"cross-corr. with {u}", ch.cross_correlation[u]) for u in inputs]
        for col, (title, test) in enumerate(tests):
            ax = axes[i, col]
            lags = test.lags_samples
            ax.axhspan(-test.band, test.band, color="tab:blue", alpha=0.15, label="99 % band")
            ax.vlines(lags, 0, np.nan_to_num(test.values), color="tab:red", lw=1.2)
            ax.plot(lags, test.values, ".", color="tab:red", ms=3)
            ax.axhline(0, color="black", lw=0.6)
            verdict = {True: "passes", False: "FAILS", None: "undefined"}[test.passes]
            ax.set_title(f"{ch.name}: {title} ({verdict})", fontsize=9)
            ax.grid(alpha=0.3)
            if col == 0:
                ax.set_ylabel(f"e_{ch.name} (normalized)")
            if i == n - 1:
                ax.set_xlabel("lag [samples]")
    figure.suptitle(f"{recording_name}, {run.label}: simulation residual (resid)")
    return _png(figure)


def plot_name(recording_name: str, label: str | None = None) -> str:
    """The file of a recording's ``compare`` plot, or (``label``) of a set's ``resid`` plot."""
    stem = Path(recording_name).stem
    return f"{stem}-compare.png" if label is None else f"{stem}-resid-{Path(label).stem}.png"


def plot_names(recording_names: list[str], labels: tuple[str, ...]) -> list[str]:
    """Every plot file a validation of these recordings with these labelled sets writes."""
    return [
        name
        for recording in recording_names
        for name in (plot_name(recording), *(plot_name(recording, label) for label in labels))
    ]


def plot_files(entries: tuple[RecordingResult, ...]) -> dict[str, bytes]:
    """File name -> PNG bytes for every plot of a validation (nothing written yet)."""
    files = {}
    for entry in entries:
        name = entry.recording.name()
        files[plot_name(name)] = compare_png(entry)
        for run in entry.runs:
            files[plot_name(name, run.label)] = resid_png(run, name)
    return files


def write_plots(
    entries: tuple[RecordingResult, ...], directory: Path, staging: Staging
) -> list[Path]:
    """Render every plot, staging each as a file of ``directory`` (``staging`` puts them in
    place); their paths."""
    return [staging.write(directory / name, data) for name, data in plot_files(entries).items()]
