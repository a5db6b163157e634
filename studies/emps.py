"""EMPS study: output-error fits of the real EMPS axis against the published IDIM-LS estimates,
over the length of the shooting horizon (docs/real-data.md).

The EMPS axis (models/emps_axis.py) is an integrator under closed-loop position control; fitted
from its measured controller output, a simulation of the whole record drifts. Per horizon H:
independent windows of H samples, each from its own estimated state (``continuity="none"``),
and, last, one continuous trajectory (``continuity="exact"``). Printed per fit: estimates and
their deviation from IDIM-LS, the robust 95 % intervals, residual rms, and the simulation fit
of the whole record (open loop from the estimated initial state, ``hframe_id.validation``).

    python -m studies.emps --horizons 10 20 50 100 200 500 1000
"""

from __future__ import annotations

import argparse
import sys
import time

from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.models import load_model_file
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings import read_recording
from hframe_id.resources import datasets_dir, models_dir
from hframe_id.validation.metrics import fit_percent
from hframe_id.validation.replay import simulate_channels

RECORDING = "real/emps-estimation.mcap"
PUBLISHED = "emps-idim-ls.yaml"
FITTED = ("M", "F_v", "F_c", "F_0")


def fit_row(recording, published, continuity: str, horizon: int) -> str:
    """One line: the fit at this horizon against the published set."""
    start = time.perf_counter()
    result = fit_recordings(
        [recording],
        published,
        FitOptions(shooting_interval=horizon, continuity=continuity, verbose=0),
    )
    wall = time.perf_counter() - start
    cells = []
    for name in FITTED:
        est, ref = result.estimates[name], published.values[name]
        deviation = (
            f"{est.estimate - ref:+.3f} N"
            if name == "F_0"
            else f"{100 * (est.estimate / ref - 1):+.2f} %"
        )
        cells.append(
            f"{name} {est.estimate:.4g} [{est.ci95[0]:.4g}, {est.ci95[1]:.4g}] ({deviation})"
        )
    data, simulated = simulate_channels(result.parameters, recording)
    simulation = fit_percent(data.measured[:, 0], simulated[:, 0], data.valid[:, 0])
    rms = result.diagnostics.channel_rms.get("qm", float("nan"))
    label = f"{continuity:>5} H={horizon:>5}"
    status = "ok" if result.success else f"FAILED ({result.message})"
    return (
        f"{label}: {status}; {'; '.join(cells)}; residual rms {rms * 1e6:.3g} um; "
        f"simulation fit {simulation:.2f} %; {wall:.1f} s"
    )


def main(argv: list[str] | None = None) -> int:
    """The command line of this study (``--help``); prints one line per trial."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--horizons", type=int, nargs="+", default=[10, 20, 50, 100, 200, 500])
    args = parser.parse_args(argv)
    load_model_file(models_dir() / "emps_axis.py")
    recording = read_recording(datasets_dir() / RECORDING)
    published = load_parameter_file(models_dir() / PUBLISHED, "emps-axis")
    data, simulated = simulate_channels(published, recording)
    print(
        "published IDIM-LS set: simulation fit "
        f"{fit_percent(data.measured[:, 0], simulated[:, 0], data.valid[:, 0]):.2f} %",
        flush=True,
    )
    for horizon in args.horizons:
        print(fit_row(recording, published, "none", horizon), flush=True)
    print(fit_row(recording, published, "exact", 50), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
