"""``hframe-id simulate``: open-loop simulation of any model from a parameter file.

Inputs: steps / pulses per motor (``--step``), a voltage sequence from CSV (``--csv``, the
recorder's format) or the commanded voltages of a recording (``--recording``), zero-order held
at the sample time. Outputs: every state, input and output as CSV (exact model signals), and on
request an MCAP recording of the same inputs made by the sim rig (sensor models, log format of
docs/log-format.md) and a plot. The outputs are checked before the simulation and put in place
together after it (none if any of them fails).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import TYPE_CHECKING

from hframe_id.cli.json_output import emit
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
from hframe_id.errors import OptionError

if TYPE_CHECKING:  # imported when a simulation runs, not for --help
    import numpy as np
    import pandas as pd

    from hframe_id.simulation.open_loop import SimulationResult


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``simulate`` subcommand."""
    parser = subparsers.add_parser(
        "simulate",
        help="open-loop simulation (steps, pulses, CSV or recorded voltages) to CSV / MCAP",
        description="Simulate a model open loop with zero-order-held voltages and write the "
        "signals (states, inputs, outputs, SI units in the column names) as CSV. Inputs: "
        "--step (repeatable), --csv or --recording.",
    )
    plant = parser.add_argument_group("plant (one of)")
    plant.add_argument("--params", type=Path, help="parameter file (YAML)")
    plant.add_argument(
        "--plant",
        type=Path,
        help="realistic plant file (docs/realistic-rig.md): its own friction, current limit and "
        "actuation delay; the CSV holds exact plant signals, --mcap adds sensor latency",
    )
    parser.add_argument("--variant", help="require the parameter file to be of this variant")
    source = parser.add_argument_group("input (one kind)")
    source.add_argument(
        "--step",
        action="append",
        default=[],
        metavar="MOTOR,VOLTS[,START_S[,DURATION_S]]",
        help="a step (no duration) or pulse on one motor; repeat for more (they add up)",
    )
    source.add_argument(
        "--csv", type=Path, help="voltage sequence, header 'time [s],u1 [V][,u2 [V]]'"
    )
    source.add_argument(
        "--recording", type=Path, help="MCAP recording whose commanded voltages to replay"
    )
    add_number(
        parser,
        "--duration",
        above=0,
        help="simulated time [s] (needed with --step; --csv: last row + 1 sample; "
        "--recording: its length)",
    )
    add_number(
        parser,
        "--sample-time",
        above=0,
        default=None,
        help="sample (zero-order-hold) period [s] (default 0.001; a recording's own)",
    )
    parser.add_argument(
        "--friction",
        metavar="{smooth,stick-slip,sign}",
        help="--params: Coulomb friction law, smooth (tanh, the model's; default), stick-slip "
        "(Table 2.2) or sign (discontinuous, as the EMPS benchmark simulates); a plant file has "
        "its own",
    )
    add_substeps(parser)
    parser.add_argument("--out", type=output_file("--out"), required=True, help="CSV file to write")
    parser.add_argument(
        "--mcap",
        type=output_file("--mcap", ".mcap"),
        help="also record the same inputs with the sim rig (sensor models) to this MCAP file",
    )
    add_number(parser, "--seed", int, at_least=0, default=0, help="--mcap: sensor noise seed (0)")
    parser.add_argument(
        "--plot", type=output_folder("--plot"), metavar="DIR", help="write open_loop.png here"
    )
    add_force_option(parser, "--overwrite")
    parser.add_argument(
        "--json", action="store_true", help="print one JSON object (docs/cli-json.md)"
    )
    add_quiet_option(parser)
    parser.set_defaults(handler=run)


def _inputs(args: argparse.Namespace, n_inputs: int) -> tuple[np.ndarray, float, str]:
    """(table, sample time, description) from exactly one kind of input."""
    import numpy as np

    from hframe_id.simulation.inputs import MotorStep, step_inputs

    kinds = [name for name in ("step", "csv", "recording") if getattr(args, name)]
    if len(kinds) != 1:
        raise OptionError(
            "give exactly one kind of input: --step (repeatable), --csv or --recording"
            + (f" (got {', '.join('--' + k for k in kinds)})" if kinds else "")
        )
    if args.recording:
        from hframe_id.recordings.reader import read_recording

        recording = read_recording(args.recording)
        if recording.inputs.shape[1] != n_inputs:
            raise OptionError(
                f"{args.recording}: {recording.inputs.shape[1]} input(s), the model has {n_inputs}"
            )
        dt = args.sample_time or recording.sample_period_s
        if not math.isclose(dt, recording.sample_period_s, rel_tol=1e-9):
            raise OptionError(
                f"{args.recording} is sampled at {recording.sample_period_s} s; drop --sample-time"
            )
        table = np.nan_to_num(recording.inputs, nan=0.0)
        if args.duration is not None:
            table = table[: max(1, int(round(args.duration / dt)))]
        return table, dt, f"recording {args.recording.name}"
    dt = args.sample_time or 1e-3
    if args.csv:
        from hframe_id.rig.protocols import load_sequence_csv

        protocol = load_sequence_csv(args.csv, args.duration)
        check_length(protocol.duration_s or protocol.time_s[-1] + dt, dt, "--csv")
        if protocol.n_inputs != n_inputs:
            raise OptionError(
                f"{args.csv}: {protocol.n_inputs} voltage column(s), the model has {n_inputs}"
            )
        return protocol.table(dt), dt, f"sequence {args.csv.name}"
    if args.duration is None:
        raise OptionError("--step needs --duration (simulated time [s])")
    check_length(args.duration, dt, "--duration")
    steps = [MotorStep.parse(text) for text in args.step]
    return step_inputs(steps, n_inputs, args.duration, dt), dt, "steps " + " ".join(args.step)


def _frame(result: SimulationResult) -> pd.DataFrame:
    import numpy as np
    import pandas as pd

    data = {"time [s]": result.time_s}
    for j, label in enumerate(result.input_labels):
        data[label] = np.append(result.inputs[:, j], np.nan)  # nothing is held after t_N
    for j, label in enumerate(result.output_labels):
        data[f"output {label}"] = result.outputs[:, j]
    for j, label in enumerate(result.state_labels):
        data[f"state {label}"] = result.states[:, j]
    return pd.DataFrame(data)


#: The file ``--plot DIR`` gets.
PLOT_FILE = "open_loop.png"


def _check_writable(args: argparse.Namespace) -> None:
    for option, path in (("--out", args.out), ("--mcap", args.mcap)):
        if path is not None:
            check_file(path, option, args.force)
    if args.plot is not None:
        check_dir(args.plot, "--plot", files=(PLOT_FILE,), force=args.force)


def _record(args, params, table: np.ndarray, dt: float, n_substeps: int, source: str, out: Path):
    """Record the inputs with the sim rig to ``out`` (--mcap's staged file, replaced); the
    logger's ``RunSummary``."""
    from hframe_id.rig.logger import RunOptions, run_experiment
    from hframe_id.rig.protocols import SequenceProtocol
    from hframe_id.rig.sim import SimRig
    from hframe_id.simulation.inputs import change_points

    times, volts = change_points(table, dt)
    protocol = SequenceProtocol(times, volts, table.shape[0] * dt, source=source)
    rig = SimRig(params, seed=args.seed, sample_period_s=dt, paced=False, n_substeps=n_substeps)
    try:
        summary = run_experiment(
            rig,
            protocol,
            RunOptions(
                out=out,
                overwrite=True,
                reproducible=True,
                handle_signals=False,
                notes=f"hframe-id simulate: {source}",
            ),
        )
    finally:
        rig.close()
    return summary


def _load_plant(args: argparse.Namespace):
    """(plant or parameter set, its model) from --plant or --params."""
    from hframe_id.models import build_model
    from hframe_id.parameters import load_parameter_file

    if (args.params is None) == (args.plant is None):
        raise OptionError("give one of --params (a parameter file) or --plant (a plant file)")
    if args.plant is None:
        params = load_parameter_file(args.params, args.variant)
        return params, build_model(params.variant)
    from hframe_id.rig.plant import load_plant_file

    if args.friction is not None:
        raise OptionError("--friction is for --params; a plant file sets its own friction")
    plant = load_plant_file(args.plant)
    if args.variant is not None and plant.variant != args.variant:
        raise OptionError(f"{args.plant}: plant is {plant.variant!r}, --variant {args.variant!r}")
    return plant, plant.model


def _simulate(args, plant, model, table: np.ndarray, dt: float) -> tuple[SimulationResult, int]:
    """The CSV's signals and the RK4 substeps used."""
    from hframe_id.rig.plant import Plant
    from hframe_id.simulation.friction import FrictionOptions
    from hframe_id.simulation.open_loop import run_open_loop

    if isinstance(plant, Plant):
        from hframe_id.rig.realistic import run_plant

        n = args.substeps or plant.substeps(dt)
        return run_plant(plant, table, dt, n), n
    from hframe_id.simulation.open_loop import default_substeps

    friction = FrictionOptions(args.friction or "smooth")
    if args.mcap is not None and friction.model != "smooth":
        raise OptionError(
            "--mcap records with the sim rig, which simulates smooth friction only (a plant "
            "file gives it stick-slip)"
        )
    p = model.parameter_vector(plant.values)
    n = args.substeps or default_substeps(model, p, dt, friction)
    return run_open_loop(model, p, table, dt, friction=friction, n_substeps=args.substeps), n


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id simulate``: open loop to CSV, optionally an MCAP recording and a plot."""
    import numpy as np

    if args.mcap is None and args.seed != 0:  # was ignored without a word
        raise OptionError("--seed is for --mcap (the sim rig's sensor noise)")
    plant, model = _load_plant(args)
    _check_writable(args)
    table, dt, source = _inputs(args, model.n_inputs)
    progress = Progress(args.quiet)
    with progress.slow(f"simulating {table.shape[0] * dt:g} s of {model.variant} ({source})"):
        result, n = _simulate(args, plant, model, table, dt)
    if not np.isfinite(result.states).all():
        raise OptionError("the simulation diverged (non-finite states); try more --substeps")
    law = "plant's" if args.plant else f"{args.friction or 'smooth'}"
    report = {
        "csv": args.out,
        "samples": table.shape[0],
        "sample_time_s": dt,
        "model": model.variant,
        "friction": law,
        "source": source,
        "substeps": n,
        "outputs": [
            {
                "name": signal.name,
                "unit": signal.unit,
                "final": result.outputs[-1, j],
                "min": result.outputs[:, j].min(),
                "max": result.outputs[:, j].max(),
            }
            for j, signal in enumerate(model.outputs)
        ],
        "mcap": None,
        "plot": None,
    }
    lines = [
        f"wrote {args.out} ({table.shape[0]} samples of {dt * 1e3:g} ms, {model.variant}, "
        f"{law} friction, {source})"
    ]
    with written_together() as staging:
        _frame(result).to_csv(staging.file(args.out), index=False)
        if args.mcap is not None:
            with progress.slow(f"recording {args.mcap} with the sim rig"):
                summary = _record(args, plant, table, dt, n, source, staging.file(args.mcap))
            state = f"aborted: {summary.abort_reason}" if summary.aborted else "complete"
            report["mcap"] = {
                "file": args.mcap,
                "samples": summary.samples,
                "seed": args.seed,
                "aborted": summary.aborted,
                "abort_reason": summary.abort_reason or None,
            }
            lines.append(
                f"wrote {args.mcap} ({summary.samples} samples, sim rig, seed {args.seed}, {state})"
            )
        if args.plot is not None:
            from hframe_id.simulation.plots import write_open_loop_plot

            title = f"{model.variant}: {source}"
            write_open_loop_plot(result, staging.file(args.plot / PLOT_FILE), title)
            report["plot"] = args.plot / PLOT_FILE
            lines.append(f"wrote {report['plot']}")
    if args.json:
        emit("simulate", report)
    else:
        print("\n".join(lines))
    return 0
