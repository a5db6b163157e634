"""The fleet report: each parameter over time per rig with its 95 % intervals, and the drift
flags (``hframe_id.fleet.drift``) as a table, a markdown page and JSON.

Figures are ``matplotlib.figure.Figure`` objects drawn by the Agg canvas (matplotlib imported
inside :func:`plot_histories`), as in ``hframe_id.fitting.report``: importing this module sets
no backend and no global state.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pandas as pd

from hframe_id.atomic import Staging
from hframe_id.fleet.drift import Drift, parameters_of, structure_changes, successful

JSON_FORMAT_VERSION = "1.0"


def plot_histories(
    frame: pd.DataFrame, threshold: float, out: Path, staging: Staging
) -> list[Path]:
    """One PNG per parameter in the folder ``out``, staged to replace it as a whole
    (``staging`` puts it in place): per rig, the estimate's change against the rig's first
    successful run [%] over run time, with its 95 % interval as error bars and the drift
    threshold as dashed lines. Runs whose fit did not identify the parameter (never judged,
    ``drift``) are hollow, and the view holds the changes and the threshold, not the
    intervals (``change_view``): on a realistic fleet one poorly determined k_b had an
    interval of 5e22 %, and every other run of every rig was drawn flat at 0.
    Returns the PNGs' paths in ``out``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ok = successful(frame)
    folder = staging.folder(out)
    names = []
    for name, unit in parameters_of(ok):
        value = f"{name} [{unit}]"
        if not ok[value].notna().any():
            continue  # no converged fit has it (matplotlib warned of an empty legend)
        fig = Figure(figsize=(7, 3.5))
        FigureCanvasAgg(fig)
        ax = fig.subplots()
        changes = []
        hollow = "not identified (not judged)"  # the legend's entry, once
        for rig, runs in ok[ok[value].notna()].groupby("rig", sort=True):
            base = runs[value].iloc[0]
            change = 100 * (runs[value] / base - 1)
            low = 100 * (runs[f"{name} ci95 low [{unit}]"] / base - 1)
            high = 100 * (runs[f"{name} ci95 high [{unit}]"] / base - 1)
            bars = ax.errorbar(
                runs["run_time"],
                change,
                yerr=[change - low, high - change],
                marker="o",
                capsize=3,
                label=str(rig),
            )
            loose = ~runs.get(f"{name} identified", pd.Series(True, index=runs.index)).astype(bool)
            ax.plot(
                runs["run_time"][loose],
                change[loose],
                "o",
                color=bars[0].get_color(),
                markerfacecolor="white",
                zorder=3,
                label=hollow if loose.any() else None,
            )
            hollow = None if loose.any() else hollow
            changes.extend(change.tolist())
        for level in (-100 * threshold, 100 * threshold):
            ax.axhline(level, color="0.5", linestyle="--", linewidth=0.8)
        ax.set_ylim(*change_view(changes, 100 * threshold))
        ax.set_title(f"{value}: change against each rig's first run")
        ax.set_ylabel("change [%]")
        ax.set_xlabel("run time [UTC]")
        ax.legend(fontsize="small", ncol=2, loc="best")
        fig.autofmt_xdate()
        fig.tight_layout()
        fig.savefig(folder / f"{name}.png", dpi=90)
        names.append(f"{name}.png")
    return [out / n for n in names]


def change_view(changes: list[float], threshold: float) -> tuple[float, float]:
    """The y-limits [%] of a history plot: every change and +/- ``threshold`` [%], with a
    tenth of that span to spare on each side (intervals reaching beyond are cut at the
    edge)."""
    finite = [c for c in changes if math.isfinite(c)]
    low, high = min([-threshold, *finite]), max([threshold, *finite])
    pad = 0.1 * (high - low)
    return low - pad, high + pad


def flags_table(drifts: list[Drift]) -> list[list[str]]:
    """Header and one row per flagged (rig, parameter)."""
    rows = [
        [
            "rig",
            "parameter",
            "baseline",
            "latest",
            "change [%]",
            "z",
            "fleet scatter [%]",
            "z against it (critical)",
            "runs",
        ]
    ]
    for d in drifts:
        if d.flagged:
            rows.append(
                [
                    d.rig,
                    f"{d.parameter} [{d.unit}]",
                    f"{d.baseline:.5g}",
                    f"{d.latest:.5g}",
                    f"{100 * d.change:+.1f}",
                    f"{d.z:+.1f}",
                    "-" if math.isnan(d.scatter) else f"{100 * d.scatter:.1f}",
                    "-"
                    if math.isnan(d.z_scatter)
                    else f"{d.z_scatter:+.2f} ({d.scatter_critical:.2f})",
                    str(d.runs),
                ]
            )
    return rows


def format_table(rows: list[list[str]]) -> str:
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]))]
    return "\n".join(
        "  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip() for row in rows
    )


def summary(
    frame: pd.DataFrame, drifts: list[Drift], threshold: float, results: Path, plots: Path
) -> dict[str, Any]:
    """The report as JSON: counts, the threshold and the ``flagged`` list."""
    return {
        "format_version": JSON_FORMAT_VERSION,
        "results": str(results),
        "threshold": threshold,
        "rigs": int(frame["rig"].nunique()),
        "fits": len(frame),
        "by_status": {str(k): int(v) for k, v in frame["status"].value_counts().items()},
        "plots": str(plots),
        "structure_changes": structure_changes(frame),
        "flagged": [
            {
                "rig": d.rig,
                "parameter": d.parameter,
                "change": d.change,
                "unit": d.unit,
                "baseline": d.baseline,
                "latest": d.latest,
                "z": d.z,
                "scatter": None if math.isnan(d.scatter) else d.scatter,
                "z_scatter": None if math.isnan(d.z_scatter) else d.z_scatter,
                "scatter_critical": (
                    None if math.isnan(d.scatter_critical) else d.scatter_critical
                ),
            }
            for d in drifts
            if d.flagged
        ],
    }


def structure_lines(changes: dict[str, list[str]]) -> list[str]:
    """One line per rig whose fits kept different models (``drift.structure_changes``)."""
    return [
        f"{rig}: its fits kept {' then '.join(models)}; drift is judged over its "
        f"{models[-1]} fits only"
        for rig, models in changes.items()
    ]


def write_markdown(
    report: dict[str, Any], drifts: list[Drift], plots: list[Path], path: Path, staging: Staging
) -> Path:
    """Stage a markdown page at ``path`` with the counts, the flags table and the ``plots``
    (``staging`` puts it in place)."""
    rows = flags_table(drifts)
    lines = [
        "# Fleet report",
        "",
        f"{report['fits']} fits of {report['rigs']} rigs from `{report['results']}` "
        f"({', '.join(f'{n} {s}' for s, n in report['by_status'].items())}). Drift: change "
        f"of the latest run against the rig's first of at least {100 * report['threshold']:g} "
        "% with the 95 % interval of the difference excluding zero, and standing out at 95 % "
        "against the other rigs' week-to-week scatter (fleet scatter: relative std of a "
        "healthy estimate; critical: the 95 % critical value of |z| against a scatter "
        "estimated from that few changes).",
        "",
        "## Flagged",
        "",
    ]
    if len(rows) > 1:
        lines += ["| " + " | ".join(rows[0]) + " |", "|" + " --- |" * len(rows[0])]
        lines += ["| " + " | ".join(row) + " |" for row in rows[1:]]
    else:
        lines.append("No drift flagged.")
    changes = structure_lines(report["structure_changes"])
    if changes:
        lines += ["", "## Structure", "", *(f"- {line}" for line in changes)]
    lines += ["", "## Histories", ""]
    for png in sorted(plots):
        lines.append(f"![{png.stem}]({png.parent.name}/{png.name})")
    return staging.write(path, "\n".join(lines) + "\n")
