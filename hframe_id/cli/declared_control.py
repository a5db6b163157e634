"""``hframe-id control --controller FILE.py --reference REC``: any model under a declared
controller, on a recording's references and disturbances.

The H-frame's path options (square, points) and its PID gains are the thesis's Chapter 5; a
declared controller (docs/custom-models.md) reads its references from a recording instead, so
any model (the thesis's or one declared in a model file) runs under it. Prints per command its
range and the share of samples at which it saturates, per output its range and, where the
recording measures it, the rms deviation of the simulation from the measurement.
"""

from __future__ import annotations

import argparse

from hframe_id.cli.outputs import check_file, check_length, written_together
from hframe_id.cli.progress import Progress
from hframe_id.control.trajectory import SQUARE_F_A, SQUARE_SIDE_M, SQUARE_V_MAX_M_PER_S
from hframe_id.errors import ControllerError, OptionError

#: Options of the H-frame PID path that a declared controller does not use, with their
#: defaults: giving one with ``--controller`` is an error, not silently ignored.
PID_ONLY = {
    "kp": None,
    "ki": 0.0,
    "kd": 0.0,
    "motor2_gain_scale": 1.0,
    "sample_time": None,
    "delay_samples": 0,
    "trajectory": "square",
    "side": SQUARE_SIDE_M,
    "v_max": SQUARE_V_MAX_M_PER_S,
    "f_a": SQUARE_F_A,
    "points": None,
    "dwell": 0.0,
    "settle": None,
    "plot": None,
    "workspace": None,
}


def check_options(args: argparse.Namespace) -> None:
    """Raise ``OptionError`` for a missing ``--reference`` or an H-frame-only option."""
    if args.reference is None:
        raise OptionError(
            "--controller needs --reference REC.mcap: the recording whose signals it reads"
        )
    given = [name for name, default in PID_ONLY.items() if getattr(args, name) != default]
    if given:
        flags = ", ".join("--" + name.replace("_", "-") for name in given)
        raise OptionError(
            f"{flags}: for the H-frame PID (--kp ...); a declared controller has its own "
            "gains and timing, and --plot draws the H-frame's figures (use --csv)"
        )


def check_loop_length(controller, recording, option: str) -> None:
    """Refuse, before any work, a closed loop of more than ``MAX_SAMPLES`` samples of the
    controller's period over ``recording`` (a sample period function giving 1e-12 s asked
    for 181 TiB of time stamps, an ArrayMemoryError traceback)."""
    duration_s = float(recording.time_s[-1] - recording.time_s[0])
    check_length(duration_s, controller.sample_period(recording), option)


def summary(model, controller, run, recording) -> dict:
    """Per command: range and share of samples beyond its limits (saturated); per output:
    range and rms deviation from the recording where it measures the output."""
    import numpy as np

    commands = {}
    for j, signal in enumerate(controller.commands):
        column = run.commands[:, j]
        lower, upper = controller.limit(signal.name)
        commands[signal.name] = {
            "unit": signal.unit,
            "min": float(column.min()),
            "max": float(column.max()),
            "saturated_percent": float(100 * np.mean((column <= lower) | (column >= upper))),
        }
    outputs = np.array(model.output.map(run.time_s.size)(run.states.T)).T
    n = min(run.time_s.size, recording.n_samples)
    signals = {}
    for j, signal in enumerate(model.outputs):
        deviation = None
        if signal.name in recording.output_names:
            measured = recording.outputs[:n, recording.output_names.index(signal.name)]
            error = (outputs[:n, j] - measured)[np.isfinite(measured)]
            deviation = float(np.sqrt(np.mean(error**2)))
        signals[signal.name] = {
            "unit": signal.unit,
            "min": float(outputs[:, j].min()),
            "max": float(outputs[:, j].max()),
            "rms_deviation": deviation,
        }
    return {"commands": commands, "outputs": signals}


def _signals(model, controller, run):
    import pandas as pd

    frame = {"time [s]": run.time_s}
    for j, s in enumerate(controller.references):
        frame[f"{s.name} [{s.unit}]"] = run.references[:, j]
    for j, s in enumerate(model.states):
        frame[f"{s.name} [{s.unit}]"] = run.states[:, j]
    for j, s in enumerate(controller.commands):
        frame[f"{s.name} command [{s.unit}]"] = run.commands[:, j]
    for j, s in enumerate(model.inputs):
        frame[f"{s.name} applied [{s.unit}]"] = run.inputs[:, j]
    return pd.DataFrame(frame)


def run(args: argparse.Namespace) -> int:
    """Simulate ``--params``'s model under ``--controller`` on ``--reference``'s signals."""
    import numpy as np

    from hframe_id.cli.fit_command import resolve_dataset
    from hframe_id.control import load_controller_file
    from hframe_id.control.loop import simulate_loop
    from hframe_id.models import build_model
    from hframe_id.parameters import load_parameter_file
    from hframe_id.recordings import read_recording
    from hframe_id.simulation.friction import FrictionOptions
    from hframe_id.validation.replay import channels, rest_state

    check_options(args)
    friction = FrictionOptions(args.friction)
    if args.csv is not None:
        check_file(args.csv, "--csv", args.force)
    controller = load_controller_file(args.controller)
    recording = read_recording(resolve_dataset(str(args.reference)))
    check_loop_length(controller, recording, f"--controller {args.controller}")
    params = load_parameter_file(args.params, args.variant)
    model = build_model(params.variant)
    p = model.parameter_vector(params.values)
    measures = all(s.name in recording.output_names for s in model.outputs)
    fits = tuple(s.name for s in model.inputs) == tuple(recording.input_names)
    # From rest at the first measured positions, as validate's runs; else from rest at zero.
    x0 = rest_state(model, p, channels(model, recording)) if measures and fits else None
    if x0 is None:
        x0 = np.zeros(model.n_states)
    what = f"simulating {args.reference} under {controller.name}"
    with Progress(args.quiet).slow(what):
        result = simulate_loop(model, p, controller, recording, x0, friction, args.substeps)
    if not result.stable:
        raise ControllerError(
            f"{controller.where}: unstable closed loop with {args.params}: the simulation "
            f"diverged at t = {result.diverged_at_s:.4g} s"
        )
    with written_together() as staging:
        if args.csv is not None:
            _signals(model, controller, result).to_csv(staging.file(args.csv), index=False)
    document = {
        "params": str(args.params),
        "variant": params.variant,
        "controller": controller.name,
        "controller_file": str(controller.controller_file),
        "reference": recording.name(),
        "samples": int(result.time_s.size),
        "sample_period_s": result.sample_period_s,
        "friction": friction.model,
        "substeps": result.n_substeps,
        "disturbances": list(result.disturbances),
        **summary(model, controller, result, recording),
    }
    if args.json:
        from hframe_id.cli import json_output

        print(json_output.text(document))
        return 0
    print(
        f"{params.variant} ({args.params}), controller {controller.name} "
        f"({controller.controller_file.name}), reference {recording.name()}: "
        f"{result.time_s.size} samples at {1e3 * result.sample_period_s:.9g} ms, "
        f"{friction.model} friction"
    )
    print(f"{'command':<10} {'min':>10} {'max':>10}  saturated [%]")
    for name, c in document["commands"].items():
        print(f"{name:<10} {c['min']:>10.4g} {c['max']:>10.4g}  {c['saturated_percent']:>13.2f}"
              f"  [{c['unit']}]")  # fmt: skip
    print(f"{'output':<10} {'min':>10} {'max':>10}  rms deviation from the recording")
    for name, o in document["outputs"].items():
        deviation = "-" if o["rms_deviation"] is None else f"{o['rms_deviation']:.4g}"
        print(f"{name:<10} {o['min']:>10.4g} {o['max']:>10.4g}  {deviation}  [{o['unit']}]")
    if args.csv is not None:
        print(f"wrote {args.csv}")
    return 0
