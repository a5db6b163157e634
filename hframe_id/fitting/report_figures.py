"""The fit report's figures, drawn from plain arrays: one figure per experiment (measured,
fitted and reference outputs with the residuals) and the free parameters' correlation map.

The functions take only numbers and strings (``ExperimentSignals``, a correlation matrix), so
they can run in another process (``hframe_id.figure_drawers``) that imports nothing but numpy
and matplotlib. Figures are ``matplotlib.figure.Figure`` objects on an Agg canvas: no pyplot,
no backend switch, no global state.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: Display scale per output unit: angles in rad, positions in mm (other units: SI, ``shown_in``).
SCALE = {"rad": (1.0, "rad"), "m": (1e3, "mm")}
RESIDUAL_SCALE = {"rad": (1e6, "urad"), "m": (1e6, "um")}
#: Resolution of the report's PNGs [dots per inch].
DPI = 90
#: zlib level of the PNGs: 1 encodes the shipped fit's experiment figure in 25 ms instead of
#: 44 ms (level 6, the default), for a file 17 % larger.
PNG_OPTIONS = {"compress_level": 1}


def shown_in(unit: str, scales: dict[str, tuple[float, str]] = SCALE) -> tuple[float, str]:
    """(factor, unit) an output in SI ``unit`` is shown in: its entry of ``scales``
    (``SCALE``, ``RESIDUAL_SCALE``), else the SI unit itself (a speed, a current)."""
    return scales.get(unit, (1.0, unit))


@dataclass(frozen=True)
class ExperimentSignals:
    """What the figure of one experiment shows, in SI units.

    time_s : (N,) sample times [s].
    names, units : the output channels and their SI units (``"rad"``, ``"m"``, ``"rad/s"``).
    measured : (N, n_y) measured outputs, NaN where a sample is not valid.
    fitted : (N, n_y) outputs simulated with the fitted parameters.
    reference : (N, n_y) the same with the reference set, or None.
    title : the figure's title (the recording's name).
    """

    time_s: np.ndarray
    names: tuple[str, ...]
    units: tuple[str, ...]
    measured: np.ndarray
    fitted: np.ndarray
    reference: np.ndarray | None
    title: str


def _figure(size: tuple[float, float], margins: tuple[float, float, float, float]):
    """A figure on the Agg canvas with fixed ``margins`` (left, right, bottom, top) [in]: a
    layout engine would draw every figure twice."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    width, height = size
    left, right, bottom, top = margins
    figure = Figure(figsize=size)
    figure.subplots_adjust(
        left=left / width, right=1 - right / width, bottom=bottom / height, top=1 - top / height
    )
    FigureCanvasAgg(figure)
    return figure


def import_matplotlib() -> None:
    """Import what the figures need (0.47 s), e.g. in a worker before its first figure. (A
    first figure drawn here as well was measured not to shorten the later ones.)"""
    import matplotlib.backends.backend_agg  # noqa: F401
    import matplotlib.figure  # noqa: F401


def plot_experiment(signals: ExperimentSignals, label: str, path: Path) -> None:
    """Measured, fitted and reference (labelled ``label``) outputs of one experiment over
    the fit's residuals, one column per channel, as a PNG at ``path``."""
    n = len(signals.names)
    fig = _figure((4.2 * n, 6), (0.9, 0.15, 0.5, 0.6))
    fig.subplots_adjust(wspace=0.45, hspace=0.15)
    axes = fig.subplots(2, n, sharex=True, squeeze=False)
    t = signals.time_s
    for j, (name, unit) in enumerate(zip(signals.names, signals.units, strict=True)):
        scale, shown = shown_in(unit)
        rscale, rshown = shown_in(unit, RESIDUAL_SCALE)
        ax = axes[0, j]
        ax.plot(t, scale * signals.measured[:, j], "k.", ms=1.5, label="measured (valid)")
        ax.plot(t, scale * signals.fitted[:, j], "C0", lw=1.2, label="fitted")
        if signals.reference is not None:
            ax.plot(t, scale * signals.reference[:, j], "C3--", lw=1, label=f"reference: {label}")
        # An explicit y spares matplotlib the search for the title's position (16 % of
        # the figure's drawing time).
        ax.set_title(f"{name} [{shown}]", y=1.0)
        ax.grid(alpha=0.3)
        res = axes[1, j]
        res.plot(t, rscale * (signals.measured[:, j] - signals.fitted[:, j]), "C0", lw=0.8)
        res.set_ylabel(f"measured - fitted [{rshown}]")
        res.set_xlabel("time [s]")
        res.grid(alpha=0.3)
    for ax in axes.flat:
        ax.locator_params(nbins=4)  # a tick costs ~1 ms to draw; 4 bins read as well
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(signals.title)
    fig.savefig(path, dpi=DPI, pil_kwargs=PNG_OPTIONS)


def plot_correlation(correlation: np.ndarray, names: tuple[str, ...], path: Path) -> None:
    """The lower triangle of a correlation matrix as a heat map with the value in every cell
    below the diagonal (the matrix is symmetric and its diagonal is 1), as a PNG at ``path``."""
    correlation = np.asarray(correlation, dtype=float)
    size = 0.6 * len(names)
    fig = _figure((size + 2.5, size + 1.5), (1.2, 0.3, 1.2, 0.4))
    ax = fig.subplots()
    lower = np.where(np.tril(np.ones_like(correlation, dtype=bool)), correlation, np.nan)
    image = ax.imshow(lower, cmap="RdBu_r", vmin=-1, vmax=1)
    for i, j in zip(*np.tril_indices(len(names), k=-1), strict=True):
        r = correlation[i, j]
        colour = "white" if abs(r) > 0.6 else "black"
        ax.text(j, i, f"{r:.2f}", ha="center", va="center", fontsize=7, color=colour)
    ax.set_xticks(range(len(names)), names, rotation=90, fontsize=8)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)
    fig.colorbar(image, ax=ax, shrink=0.8, label="correlation")
    ax.set_title("Correlation of the free parameters")
    fig.savefig(path, dpi=DPI, pil_kwargs=PNG_OPTIONS)
