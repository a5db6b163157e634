"""Plot of an open-loop run (``hframe-id simulate --plot``), built without pyplot (Agg canvas)."""

from __future__ import annotations

from pathlib import Path

from matplotlib.figure import Figure

from hframe_id.simulation.open_loop import SimulationResult


def open_loop_figure(result: SimulationResult, title: str = "") -> Figure:
    """Inputs and outputs of an open-loop run, one axis per output unit."""
    time_s, inputs, outputs = result.time_s, result.inputs, result.outputs
    input_labels, output_labels = result.input_labels, result.output_labels
    units = sorted({label.split("[")[-1].rstrip("]") for label in output_labels})
    fig = Figure(figsize=(8.0, 2.4 * (len(units) + 1)), layout="constrained")
    axes = fig.subplots(len(units) + 1, 1, sharex=True)
    for j, label in enumerate(input_labels):
        axes[0].step(time_s[: inputs.shape[0]], inputs[:, j], where="post", label=label)
    axes[0].set_ylabel("input [V]")
    for ax, unit in zip(axes[1:], units, strict=True):
        for j, label in enumerate(output_labels):
            if label.endswith(f"[{unit}]"):
                ax.plot(time_s, outputs[:, j], label=label)
        ax.set_ylabel(f"[{unit}]")
    for ax in axes:
        ax.grid(True, linewidth=0.3)
        ax.legend(loc="best", fontsize="small")
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(title or "Open-loop simulation")
    return fig


def write_open_loop_plot(result: SimulationResult, path: Path, title: str = "") -> Path:
    """Write ``open_loop_figure`` as PNG to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    open_loop_figure(result, title).savefig(path, dpi=110)
    return path
