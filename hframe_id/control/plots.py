"""The thesis's views of a closed-loop run (Fig. 5.9, 5.11, 5.13, 5.18) as PNG files.

Figures are built with ``matplotlib.figure.Figure`` (no pyplot, no global backend state) and
written by the Agg canvas.
"""

from __future__ import annotations

from pathlib import Path

from matplotlib.figure import Figure

from hframe_id.atomic import Staging
from hframe_id.control.closed_loop import ClosedLoopResult
from hframe_id.control.metrics import perpendicular_error

FIGURES = {
    "path": "fig5_9_path.png",
    "perpendicular": "fig5_11_perpendicular_error.png",
    "motor_errors": "fig5_13_motor_angle_errors.png",
    "integrals": "fig5_18_integral_terms.png",
}


def _legs(ax, result: ClosedLoopResult) -> None:
    for leg in result.trajectory.legs:
        ax.axvline(leg.t_start_s, color="0.8", linewidth=0.8, zorder=0)
    ax.axvline(result.trajectory.legs[-1].t_end_s, color="0.8", linewidth=0.8, zorder=0)


def path_figure(result: ClosedLoopResult, title: str = "") -> Figure:
    """Fig. 5.9 (and 5.10): end-effector path vs the desired path [mm]."""
    fig = Figure(figsize=(6.4, 6.0), layout="constrained")
    ax = fig.add_subplot()
    ax.plot(*(1e3 * result.reference_xy_m.T), "k--", linewidth=1, label="desired")
    ax.plot(*(1e3 * result.xy_m.T), linewidth=1.5, label="end-effector")
    ax.plot(
        *(1e3 * result.xy_from_encoders_m.T),
        linewidth=0.8,
        linestyle=":",
        label="from motor angles (eq. 5.12)",
    )
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, linewidth=0.3)
    ax.legend(loc="center")
    ax.set_title(title or f"End-effector path, {result.controller.describe()}")
    return fig


def _time_figure(result: ClosedLoopResult, curves: list[tuple], ylabel: str, title: str) -> Figure:
    """A figure over time with the leg boundaries marked; ``curves`` are (y, plot kwargs)."""
    fig = Figure(figsize=(8.0, 4.0), layout="constrained")
    ax = fig.add_subplot()
    for values, style in curves:
        ax.plot(result.time_s, values, **style)
    _legs(ax, result)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.grid(True, linewidth=0.3)
    ax.legend()
    ax.set_title(title)
    return fig


def perpendicular_figure(result: ClosedLoopResult, title: str = "") -> Figure:
    """Fig. 5.11: error perpendicular to the leg being driven [um] (above / right positive)."""
    t = result.time_s
    curves = [
        (1e6 * perpendicular_error(t, result.xy_m, result.trajectory), {"label": "end-effector"}),
        (
            1e6 * perpendicular_error(t, result.xy_from_encoders_m, result.trajectory),
            {"linestyle": "--", "label": "from motor angles (eq. 5.12)"},
        ),
    ]
    return _time_figure(
        result,
        curves,
        "error perpendicular to the leg [um]",
        title or "Perpendicular end-effector error per leg",
    )


def motor_error_figure(result: ClosedLoopResult, title: str = "") -> Figure:
    """Fig. 5.13: actual minus desired motor angle [mrad]."""
    curves = [(1e3 * result.motor_error_rad[:, i], {"label": f"motor {i + 1}"}) for i in range(2)]
    return _time_figure(result, curves, "phi - phi_desired [mrad]", title or "Motor-angle errors")


def integral_figure(result: ClosedLoopResult, title: str = "") -> Figure:
    """Fig. 5.18: the PID integral terms (K_I times the error integral) [V]."""
    curves = [(result.integral_v[:, i], {"label": f"motor {i + 1}"}) for i in range(2)]
    return _time_figure(result, curves, "integral term I [V]", title or "PID integral terms")


def write_control_plots(
    result: ClosedLoopResult, directory: Path, staging: Staging, prefix: str = ""
) -> dict[str, Path]:
    """Stage the four figures as files of ``directory`` (``staging`` puts them in place);
    returns their paths by kind."""
    builders = {
        "path": path_figure,
        "perpendicular": perpendicular_figure,
        "motor_errors": motor_error_figure,
        "integrals": integral_figure,
    }
    written = {}
    for kind, build in builders.items():
        path = Path(directory) / f"{prefix}{FIGURES[kind]}"
        build(result).savefig(staging.file(path), dpi=110)
        written[kind] = path
    return written
