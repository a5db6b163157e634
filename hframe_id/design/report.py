"""What a design predicts, beside what users record without one: the report and its plot.

For the design, the thesis's six steps, a PRBS and a multisine (``baselines``; the PRBS and
the multisine of the design's duration and voltage limit), at the file's parameters:

- per free parameter, the predicted standard error [SI] and relative [%]
  (``Information.predicted_relative_std``): the larger of the textbook errors with the
  channels' noise (the sensors', or the levels the file's fit estimated from its residuals)
  and the fitter's ``noise-model`` errors (encoder quantization and laser noise along the
  predicted motion), as ``hframe-id fit``'s ``robust`` errors;
- the median relative standard error over the free parameters, and the criterion
  (``criteria``) of each experiment's Fisher information;
- how far x and y go [m] and the share of laser samples in range.

The plot shows the design's voltages against the limit and its predicted x and y against
the travel, the margin and the laser range, for every parameter set the design was made for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hframe_id.design.baselines import multisine, prbs, six_steps
from hframe_id.design.excitation import Layout
from hframe_id.design.information import Information, experiment_information
from hframe_id.design.optimise import Design, DesignOptions, Limits
from hframe_id.models import build_model
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.sensors import SensorModel


@dataclass(frozen=True)
class Prediction:
    """One experiment's predicted result: its ``label``, its duration [s], its information,
    the noise-model relative standard errors (n_f,) and its criterion value."""

    label: str
    duration_s: float
    information: Information
    relative_std: np.ndarray
    criterion: float

    @property
    def std_error(self) -> np.ndarray:
        """(n_f,) predicted standard errors [SI]."""
        return self.relative_std * np.abs(self.information.slopes)

    @property
    def median_relative_std(self) -> float:
        """Median over the free parameters of the relative standard error [-]."""
        return float(np.median(self.relative_std))

    @property
    def reach_m(self) -> float:
        """Largest |x| or |y| [m] of the predicted motion."""
        columns = [self.information.output_names.index(a) for a in ("x", "y")]
        return max(float(np.max(np.abs(o[:, columns]))) for o in self.information.outputs)

    @property
    def laser_share(self) -> float:
        """Share of laser samples in the laser's range [-]."""
        columns = [self.information.output_names.index(a) for a in ("x", "y")]
        valid = np.concatenate([v[:, columns].ravel() for v in self.information.valid])
        return float(np.mean(valid))


def predictions(
    design: Design,
    params: ParameterSet,
    limits: Limits,
    options: DesignOptions,
    misfit_factor: float = 1.0,
) -> list[Prediction]:
    """The design's prediction, then the six steps', the PRBS's and the multisine's, at
    ``params`` with the design's free parameters and rig, their standard errors times
    ``misfit_factor`` (``calibration``; 1: a model that matches the plant)."""
    layout = Layout(design.table.shape[0] * options.sample_period_s, options.sample_period_s)
    fit_options = design.fit_options
    dt = options.sample_period_s
    others = {
        "six steps (thesis)": six_steps(params.variant, dt),
        "PRBS": [prbs(layout, limits.max_voltage_v)],
        "multisine": [multisine(layout, limits.max_voltage_v)],
    }
    focus = design.criterion.indices(design.information.names) if design.criterion.focus else None
    infos = {"design": design.information}
    for label, tables in others.items():
        infos[label] = experiment_information(params, tables, fit_options, options.sensors, dt)
    result = []
    for label, info in infos.items():
        duration = sum(o.shape[0] for o in info.outputs) * dt
        value = design.criterion.value(info.matrix + design.prior[0], focus)
        std = info.predicted_relative_std() * misfit_factor
        result.append(Prediction(label, duration, info, std, value))
    return result


def _percent(value: float) -> str:
    return f"{100 * value:.3g}" if math.isfinite(value) else "inf"


def markdown(
    design: Design,
    rows: list[Prediction],
    params: ParameterSet,
    limits: Limits,
    csv_name: str,
    plot_name: str,
    sample_period_s: float,
    misfit_factor: float = 1.0,
) -> str:
    """The report's markdown text."""
    model = build_model(params.variant)
    units = {p.name: p.unit for p in model.parameters}
    info = design.information
    fitted = dict(design.fit_options.channel_std)
    noise_text = (
        "the levels the file's fit estimated from its residuals ("
        + ", ".join(f"{n} {v:.3g}" for n, v in fitted.items())
        + " SI)"
        if fitted
        else "the sensors' specification"
    )
    travel = ", ".join(f"{a} {lo:g} to {hi:g} m" for a, (lo, hi) in limits.travel_m.items())
    lines = [
        f"# Experiment design: {csv_name}",
        "",
        f"- parameters: {params.where()} ({params.variant}: {params.title})",
        f"- criterion: {design.criterion.describe()}, averaged over the file's values and "
        f"{len(design.parameter_sets) - 1} parameter set(s) drawn around them",
        f"- duration {design.table.shape[0] * sample_period_s:g} s,"
        f" voltage limit {limits.max_voltage_v:g} V, travel {travel}, kept "
        f"{limits.margin_m:g} m inside on the model",
        f"- blocks after the 0 V pre-roll: {'; '.join(b.describe() for b in design.blocks)}",
        "- predicted travel: "
        + "; ".join(
            ", ".join(f"{a} {lo:+.3f} to {hi:+.3f} m" for a, (lo, hi) in reach.items())
            for reach in design.reach
        ),
        f"- designed in {design.wall_time_s:.1f} s",
        f"- play it: `hframe-id record --protocol csv --csv {csv_name} ...`",
        "",
        "## Predicted standard errors",
        "",
        "Standard error [SI] (relative [%]) a fit would report: the larger of the textbook",
        "error with the channels' noise and the fitter's noise-model error (encoder",
        "quantization and laser noise along the predicted motion). Channel noise: "
        + noise_text
        + (
            f". Times {misfit_factor:.3g}, the misfit factor of the recordings the file was "
            "fitted to (its reported errors over the predicted ones, model error)"
            if misfit_factor != 1.0
            else ""
        )
        + ". Six steps: 1 s each.",
        "",
        "| parameter | value | " + " | ".join(r.label for r in rows) + " |",
        "|---" * (2 + len(rows)) + "|",
    ]
    for i, name in enumerate(info.names):
        cells = [f"{name} [{units[name]}]", f"{info.values[i]:.5g}"]
        for r in rows:
            std = r.std_error[i]
            cells.append(f"{std:.3g} ({_percent(r.relative_std[i])} %)")
        lines.append("| " + " | ".join(cells) + " |")
    lines += [
        "",
        "| experiment | duration [s] | median relative std [%] | "
        f"criterion ({design.criterion.describe()}) | max abs x, y [m] | laser samples in range "
        "[%] |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.label} | {r.duration_s:g} | {_percent(r.median_relative_std)} | "
            f"{r.criterion:.4g} | {r.reach_m:.3f} | {100 * r.laser_share:.1f} |"
        )
    lines += ["", f"![inputs and predicted motion]({plot_name})", ""]
    return "\n".join(lines)


def summary(
    design: Design, rows: list[Prediction], limits: Limits, misfit_factor: float = 1.0
) -> dict:
    """The ``--json`` payload: the design and every experiment's prediction."""
    return {
        "misfit_factor": misfit_factor,
        "criterion": design.criterion.describe(),
        "value": design.value,
        "blocks": [b.describe() for b in design.blocks],
        "max_voltage_V": limits.max_voltage_v,
        "travel_m": {a: list(v) for a, v in limits.travel_m.items()},
        "margin_m": limits.margin_m,
        "reach_m": [{a: list(v) for a, v in r.items()} for r in design.reach],
        "wall_time_s": design.wall_time_s,
        "free_parameters": list(design.information.names),
        "predictions": [
            {
                "label": r.label,
                "duration_s": r.duration_s,
                "relative_std": dict(
                    zip(r.information.names, r.relative_std.tolist(), strict=True)
                ),
                "std_error": dict(zip(r.information.names, r.std_error.tolist(), strict=True)),
                "median_relative_std": r.median_relative_std,
                "criterion": r.criterion,
                "reach_m": r.reach_m,
                "laser_share": r.laser_share,
            }
            for r in rows
        ],
    }


def plot(
    design: Design, limits: Limits, sample_period_s: float, sensors: SensorModel, path: Path
) -> None:
    """The design's voltages and its predicted x and y (at the file's values and the drawn
    parameter sets) against the limits, as a PNG at ``path``."""
    from hframe_id.fitting.report_figures import _figure

    fig = _figure((9, 6), (0.8, 0.2, 0.5, 0.4))
    fig.subplots_adjust(hspace=0.3)
    top, bottom = fig.subplots(2, 1, sharex=True)
    t = np.arange(design.table.shape[0]) * sample_period_s
    for i in range(design.table.shape[1]):
        top.step(t, design.table[:, i], where="post", lw=0.9, label=f"u{i + 1}")
    for v in (-limits.max_voltage_v, limits.max_voltage_v):
        top.axhline(v, color="k", ls="--", lw=0.8)
    top.set_ylabel("voltage [V]")
    top.legend(fontsize=8, loc="upper right")
    top.grid(alpha=0.3)
    info = design.information
    for j, axis in enumerate(("x", "y")):
        column = info.output_names.index(axis)
        bottom.plot(t, info.outputs[0][:, column], f"C{j}", lw=1.2, label=f"{axis} (file)")
        (low, high) = limits.travel_m[axis]
        for edge in (low, high):
            bottom.axhline(edge, color=f"C{j}", ls="-", lw=0.6)
            bottom.axhline(
                edge + (limits.margin_m if edge == low else -limits.margin_m),
                color=f"C{j}",
                ls=":",
                lw=0.6,
            )
    for k, motion in enumerate(design.motion[1:], start=1):
        for j in range(motion.shape[1]):
            label = "drawn parameter sets" if (k, j) == (1, 0) else None
            bottom.plot(t, motion[:, j], color=f"C{j}", lw=0.6, alpha=0.5, label=label)
    for edge in (sensors.laser_min_m, sensors.laser_max_m):
        bottom.axhline(edge, color="0.5", ls="-.", lw=0.6)
    bottom.set_ylabel("predicted position [m]")
    bottom.set_xlabel("time [s]")
    bottom.legend(fontsize=8, loc="upper right")
    bottom.grid(alpha=0.3)
    fig.suptitle(
        f"{design.criterion.describe()} design: travel (solid), margin (dotted), laser range "
        "(dash-dot)"
    )
    fig.savefig(path, dpi=100)
