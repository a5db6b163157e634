"""``hframe-id control``: simulate the two motor-angle PID loops of Chapter 5 on a path, or any
model under a declared controller (``--controller``, ``hframe_id.cli.declared_control``).

Prints the per-leg path metrics of Tables 5.1-5.9 (text, or JSON with ``--json``) and with
``--plot DIR`` writes the thesis's views (Fig. 5.9, 5.11, 5.13, 5.18). All options are checked
and the run simulated before anything is written.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from hframe_id.cli.numbers import add_number, add_substeps
from hframe_id.cli.outputs import (
    add_force_option,
    check_dir,
    check_file,
    check_length,
    output_file,
    output_folder,
    written_together,
)
from hframe_id.cli.progress import Progress, add_quiet_option
from hframe_id.control.trajectory import (
    SQUARE_F_A,
    SQUARE_SIDE_M,
    SQUARE_V_MAX_M_PER_S,
    Workspace,
    point_to_point,
    square,
)
from hframe_id.errors import OptionError

if TYPE_CHECKING:  # CasADi and pandas are imported when the loop runs, not for --help
    import pandas as pd

    from hframe_id.control.pid import ControllerOptions


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``control`` subcommand."""
    parser = subparsers.add_parser(
        "control",
        help="closed-loop PID simulation on the test square or point-to-point moves",
        description="Two independent reset-windup PID loops on the motor angles (Chapter 5, "
        "Appendix A), zero-order holds at the sample time, on an H-frame model. Prints the "
        "overshoot and maximum offset of every leg (docs/control.md). Lengths in m, speeds in "
        "m/s (the thesis's 1 in square at 6 in/s: 0.0254 m, 0.1524 m/s). With --controller "
        "FILE.py --reference REC: any model (--model-file) under a declared controller, on "
        "the recording's references and disturbances (docs/custom-models.md).",
    )
    parser.add_argument(
        "--params",
        type=Path,
        required=True,
        help="parameter file: an H-frame's for the PID, any model's with --controller",
    )
    parser.add_argument("--variant", help="require the parameter file to be of this variant")
    declared = parser.add_argument_group("declared controller")
    declared.add_argument(
        "--controller",
        metavar="FILE.py",
        help="a controller file (CONTROLLER = declare_controller(...)), e.g. "
        "models/emps_controller.py; replaces the PID options and the path",
    )
    declared.add_argument(
        "--reference",
        metavar="REC.mcap",
        help="with --controller: the recording whose signals (references, disturbances) and "
        "time base the controller runs on",
    )
    gains = parser.add_argument_group("controller")
    add_number(gains, "--kp", at_least=0, help="K_P [V/rad] (required without --controller)")
    add_number(gains, "--ki", at_least=0, default=0.0, help="K_I [V/(rad s)] (0: PD)")
    add_number(gains, "--kd", at_least=0, default=0.0, help="K_D [V s/rad]")
    add_number(
        gains,
        "--motor2-gain-scale",
        above=0,
        default=1.0,
        help="multiply motor 2's gains (section 5.7 uses 1.1)",
    )
    add_number(gains, "--sample-time", above=0, help="T [s] (default 0.001)")
    add_number(
        gains,
        "--delay-samples",
        int,
        at_least=0,
        default=0,
        help="samples between computing and applying a voltage (default 0, as Fig. 5.8)",
    )
    path = parser.add_argument_group("trajectory")
    path.add_argument("--trajectory", choices=("square", "points"), default="square")
    add_number(path, "--side", above=0, default=SQUARE_SIDE_M, help="square side [m]")
    add_number(path, "--v-max", above=0, default=SQUARE_V_MAX_M_PER_S, help="leg speed v_max [m/s]")
    add_number(path, "--f-a", above=0, at_most=0.5, default=SQUARE_F_A, help="T_a / T (eq. 5.8)")
    path.add_argument(
        "--points",
        metavar="X,Y;X,Y;...",
        help="points: the path's corners [m], the first being the start",
    )
    add_number(path, "--dwell", at_least=0, default=0.0, help="points: hold at each corner [s]")
    add_number(
        path,
        "--settle",
        at_least=0,
        default=None,
        help="hold after the last leg [s] (square 0, points 0.2)",
    )
    add_number(
        path,
        "--workspace",
        nargs=4,
        metavar=("X_MIN", "X_MAX", "Y_MIN", "Y_MAX"),
        help="reachable rectangle [m] (default +/-0.1 m)",
    )
    parser.add_argument("--friction", metavar="{smooth,stick-slip,sign}", default="smooth")
    add_substeps(parser)
    out = parser.add_argument_group("output")
    out.add_argument("--json", action="store_true", help="print the metrics as JSON")
    out.add_argument(
        "--plot", type=output_folder("--plot"), metavar="DIR", help="write the four figures here"
    )
    out.add_argument(
        "--csv", type=output_file("--csv"), help="write the closed-loop signals to this CSV file"
    )
    add_force_option(out)
    add_quiet_option(out)
    parser.set_defaults(handler=run)


def _points(text: str | None) -> list[tuple[float, float]]:
    if not text:
        raise OptionError("--trajectory points needs --points 'X,Y;X,Y;...' [m]")
    points = []
    for item in text.split(";"):
        parts = item.split(",")
        try:
            x, y = (float(v) for v in parts)
        except ValueError:
            raise OptionError(f"--points: {item!r} is not 'X,Y' in m") from None
        points.append((x, y))
    return points


def build_trajectory(args: argparse.Namespace):
    """The reference path asked for: the test square (section 5.2) or point-to-point moves.

    Lengths in [m], speeds in [m/s], times in [s]; ``--settle`` defaults to 0 for the square (as
    in the thesis) and to 0.2 s for points. Raises OptionError for options that do not fit.
    """
    if args.trajectory == "square":
        if args.points is not None or args.dwell != 0.0:  # were ignored without a word
            raise OptionError("--points and --dwell are for --trajectory points")
        return square(args.side, args.v_max, args.f_a, settle_s=args.settle or 0.0)
    if args.side != SQUARE_SIDE_M:
        raise OptionError("--side is for --trajectory square")
    settle = 0.2 if args.settle is None else args.settle
    return point_to_point(_points(args.points), args.v_max, args.f_a, args.dwell, settle)


def _controller(args: argparse.Namespace) -> ControllerOptions:
    from hframe_id.control.pid import SAMPLE_PERIOD_S, ControllerOptions, PIDGains

    sample_time = SAMPLE_PERIOD_S if args.sample_time is None else args.sample_time
    gains = PIDGains(args.kp, args.ki, args.kd)
    return ControllerOptions(
        gains,
        gains.scaled(args.motor2_gain_scale),
        sample_time,
        delay_samples=args.delay_samples,
    )


def _check_outputs(args: argparse.Namespace) -> None:
    if args.csv is not None:
        check_file(args.csv, "--csv", args.force)
    if args.plot is not None:
        from hframe_id.control.plots import FIGURES

        check_dir(args.plot, "--plot", files=FIGURES.values(), force=args.force)


def _signals(result) -> pd.DataFrame:
    import numpy as np
    import pandas as pd

    frame = {"time [s]": result.time_s}
    for j, axis in enumerate(("x", "y")):
        frame[f"{axis}_desired [m]"] = result.reference_xy_m[:, j]
        frame[f"{axis} [m]"] = result.xy_m[:, j]
    for j in range(2):
        frame[f"phi{j + 1}_desired [rad]"] = result.reference_phi_rad[:, j]
        frame[f"phi{j + 1} [rad]"] = result.phi_rad[:, j]
    for j in range(2):
        frame[f"u{j + 1} [V]"] = np.append(result.voltages_v[:, j], np.nan)
        frame[f"I{j + 1} [V]"] = result.integral_v[:, j]
    return pd.DataFrame(frame)


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id control``: simulate the PID loops on the path and print the per-leg metrics.

    Checks every option and output before simulating; writes ``--csv`` and ``--plot`` after
    the run, together.
    """
    if args.controller is not None:
        from hframe_id.cli import declared_control

        return declared_control.run(args)
    if args.reference is not None:
        raise OptionError("--reference is for --controller")
    if args.kp is None:
        raise OptionError("--kp is required (or --controller FILE.py --reference REC.mcap)")

    import numpy as np

    from hframe_id.control.closed_loop import check_hframe, simulate_closed_loop
    from hframe_id.control.metrics import leg_metrics, metrics_json
    from hframe_id.models import build_model
    from hframe_id.parameters import load_parameter_file
    from hframe_id.simulation.friction import FrictionOptions

    controller = _controller(args)
    trajectory = build_trajectory(args)
    check_length(trajectory.end_time_s, controller.sample_period_s, "trajectory")
    workspace = Workspace(*args.workspace) if args.workspace else Workspace()
    workspace.check(trajectory)
    friction = FrictionOptions(args.friction)
    _check_outputs(args)
    params = load_parameter_file(args.params, args.variant)
    model = build_model(params.variant)
    check_hframe(model)
    with Progress(args.quiet).slow(
        f"simulating {trajectory.end_time_s:g} s of {model.variant} under the PID loops"
    ):
        result = simulate_closed_loop(
            model,
            model.parameter_vector(params.values),
            trajectory,
            controller,
            friction=friction,
            workspace=workspace,
            n_substeps=args.substeps,
        )
    if not np.isfinite(result.states).all():
        raise OptionError("the simulation diverged (non-finite states); try more --substeps")
    metrics = leg_metrics(result.time_s, result.xy_m, trajectory)
    written = []
    with written_together() as staging:
        if args.csv is not None:
            _signals(result).to_csv(staging.file(args.csv), index=False)
        if args.plot is not None:
            from hframe_id.control.plots import write_control_plots

            written = list(write_control_plots(result, args.plot, staging).values())
    if args.json:
        from hframe_id.cli import json_output

        document = {
            "params": str(args.params),
            "variant": params.variant,
            "controller": controller.describe(),
            "trajectory": trajectory.name,
            "friction": friction.model,
            "legs": metrics_json(metrics),
        }
        print(json_output.text(document))
    else:
        print(f"{params.variant} ({args.params}), {controller.describe()}, {trajectory.name}")
        print(f"{'leg':>4} {'overshoot [m]':>14} {'offset max [m]':>15}")
        for m in metrics:
            over = "/" if m.overshoot_m is None else f"{m.overshoot_m:.3e}"
            print(f"{m.leg:>4} {over:>14} {m.offset_max_m:>15.3e}")
    for path in [args.csv, *written]:
        if path is not None and not args.json:
            print(f"wrote {path}")
    return 0
