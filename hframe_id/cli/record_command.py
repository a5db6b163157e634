"""``hframe-id record``: run one experiment on a rig (sim or serial) and log it to MCAP."""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from hframe_id.cli.json_output import emit
from hframe_id.cli.numbers import add_number
from hframe_id.cli.outputs import add_force_option, check_file, check_length, output_file
from hframe_id.errors import OptionError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``record`` subcommand."""
    parser = subparsers.add_parser(
        "record",
        help="run an experiment on a rig and record it (MCAP)",
        description="Run a voltage protocol on a rig and record every sample to an MCAP file "
        "(docs/log-format.md). Safety is always on: voltages are clamped to the DAC range; a "
        "limit switch, a link fault, Ctrl-C, SIGTERM or SIGHUP set 0 V and end the run (the "
        "file is still finished). Exit status 0: completed; 1: aborted.",
    )
    rig = parser.add_argument_group("rig")
    rig.add_argument("--rig", choices=("sim", "serial"), required=True, help="rig backend")
    rig.add_argument("--params", type=Path, help="sim: plant parameter file (models/*.yaml)")
    rig.add_argument(
        "--plant",
        type=Path,
        help="sim: realistic plant file instead of --params (docs/realistic-rig.md)",
    )
    add_number(rig, "--seed", int, at_least=0, default=0, help="sim: sensor noise seed (default 0)")
    rig.add_argument(
        "--fast",
        action="store_true",
        help="sim: run unpaced, as fast as possible (default: real time)",
    )
    rig.add_argument("--port", help="serial: device, e.g. /dev/ttyACM0")
    add_number(
        rig,
        "--baudrate",
        int,
        above=0,
        default=2_000_000,
        help="serial: baud rate (ignored by USB CDC; default 2000000)",
    )
    add_number(
        rig,
        "--watchdog-ms",
        int,
        at_least=1,
        at_most=60_000,  # the device's limit (SerialRig), checked before the port is opened
        default=50,
        help="serial: device watchdog, 0 V after this long without a command (default 50)",
    )
    add_number(
        rig,
        "--link-timeout",
        above=0,
        default=0.1,
        help="serial: link fault after this long without a sample [s] (default 0.1)",
    )
    proto = parser.add_argument_group("protocol")
    step, pulse, sine = _OWN["step"], _OWN["pulse"], _OWN["multisine"]
    proto.add_argument("--protocol", choices=("step", "pulse", "csv", "multisine"), default="step")
    add_number(proto, "--v1", help="step: motor 1 voltage [V]")
    add_number(proto, "--v2", help="step: motor 2 voltage [V] (H-frame)")
    add_number(proto, "--step", above=0, default=step["step"], help="step: duration [s] (0.5)")
    add_number(proto, "--amplitude", help="pulse: voltage [V]")
    add_number(proto, "--width", above=0, default=pulse["width"], help="pulse: duration [s] (0.25)")
    add_number(proto, "--motor", int, at_least=1, default=pulse["motor"], help="pulse: motor (1)")
    proto.add_argument("--csv", type=Path, help="csv: file with 'time [s],u1 [V][,u2 [V]]'")
    add_number(
        proto, "--rms", above=0, default=sine["rms"], help="multisine: RMS per motor [V] (3)"
    )
    add_number(
        proto,
        "--band",
        above=0,
        nargs=2,
        default=sine["band"],
        metavar=("F_MIN", "F_MAX"),
        help="multisine: frequency band [Hz] (0.5 10)",
    )
    add_number(proto, "--period", above=0, default=sine["period"], help="multisine: period [s] (2)")
    seed = sine["protocol_seed"]
    add_number(
        proto, "--protocol-seed", int, at_least=0, default=seed, help="multisine: phase seed (0)"
    )
    add_number(
        proto,
        "--duration",
        above=0,
        default=None,
        help="record duration [s] (step/pulse default 1.0; multisine: pre-roll + period; "
        "csv: last row + 1 sample)",
    )
    add_number(
        proto,
        "--pre-roll",
        at_least=0,
        default=_PRE_ROLL_S,
        help="step/pulse/multisine: 0 V recorded before the excitation [s] (0.05)",
    )
    out = parser.add_argument_group("output")
    out.add_argument(
        "--out",
        type=output_file("--out", ".mcap"),
        required=True,
        help="recording to write (.mcap)",
    )
    add_force_option(out, "--overwrite")
    out.add_argument("--operator", help="who runs the experiment (default: login name)")
    out.add_argument("--notes", default="", help="free text for the experiment metadata")
    out.add_argument("--quiet", action="store_true", help="no progress display")
    out.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object (docs/cli-json.md) instead of the summary",
    )
    parser.set_defaults(handler=run)


#: Each protocol's own options (attribute: default); the pre-roll is every one's but csv's.
#: One given to another protocol is refused, not silently ignored (``--protocol multisine
#: --v1 5`` recorded a 3 V rms multisine).
_OWN: dict[str, dict[str, object]] = {
    "step": {"v1": None, "v2": None, "step": 0.5},
    "pulse": {"amplitude": None, "width": 0.25, "motor": 1},
    "csv": {"csv": None},
    "multisine": {"rms": 3.0, "band": (0.5, 10.0), "period": 2.0, "protocol_seed": 0},
}
_PRE_ROLL_S = 0.05


def _check_own_options(args: argparse.Namespace) -> None:
    """Refuse the options of another protocol than ``--protocol`` (``_OWN``)."""
    others = {k: v for p, own in _OWN.items() if p != args.protocol for k, v in own.items()}
    if args.protocol == "csv":
        others["pre_roll"] = _PRE_ROLL_S  # the sequence has its own start
    for name, default in others.items():
        value = getattr(args, name)
        if (tuple(value) if isinstance(value, list) else value) != default:
            owner = next((p for p, own in _OWN.items() if name in own), "step, pulse, multisine")
            raise OptionError(
                f"--{name.replace('_', '-')} is for --protocol {owner}, not {args.protocol}"
            )


def _protocol(args: argparse.Namespace, n_inputs: int):
    from hframe_id.rig.protocols import (
        MultisineProtocol,
        PulseProtocol,
        StepProtocol,
        load_sequence_csv,
    )

    _check_own_options(args)
    duration = args.duration
    if args.protocol == "step":
        if args.v1 is None:
            raise OptionError("--protocol step needs --v1 (and --v2 on an H-frame)")
        volts = (args.v1,) if n_inputs == 1 else (args.v1, args.v2)
        if n_inputs == 1 and args.v2 is not None:
            raise OptionError("this rig has one motor; drop --v2")
        if n_inputs == 2 and args.v2 is None:
            raise OptionError("this rig has two motors; give --v2 as well")
        return StepProtocol(volts, args.step, 1.0 if duration is None else duration, args.pre_roll)
    if args.protocol == "pulse":
        if args.amplitude is None:
            raise OptionError("--protocol pulse needs --amplitude")
        return PulseProtocol(
            args.amplitude,
            args.width,
            1.0 if duration is None else duration,
            args.pre_roll,
            args.motor,
            n_inputs,
        )
    if args.protocol == "multisine":
        return MultisineProtocol(
            args.rms,
            *args.band,
            args.period,
            args.pre_roll + args.period if duration is None else duration,
            args.pre_roll,
            args.protocol_seed,
            n_inputs,
        )
    if args.csv is None:
        raise OptionError("--protocol csv needs --csv FILE")
    protocol = load_sequence_csv(args.csv, duration)
    if protocol.n_inputs != n_inputs:
        raise OptionError(
            f"{args.csv}: {protocol.n_inputs} voltage column(s), the rig has {n_inputs} motor(s)"
        )
    return protocol


def make_rig(args: argparse.Namespace):
    """The rig ``--rig`` names: sim (``--params`` or ``--plant``) or serial (``--port``).

    Raises OptionError for options of the other backend.
    """
    if args.rig == "sim":
        from hframe_id.rig.sim import SimRig

        if (args.params is None) == (args.plant is None):
            raise OptionError(
                "--rig sim needs one of --params (a parameter file) or --plant (a plant file)"
            )
        if args.port is not None:
            raise OptionError("--port is for --rig serial")
        if args.plant is not None:
            from hframe_id.rig.plant import load_plant_file

            plant = load_plant_file(args.plant)
        else:
            from hframe_id.parameters import load_parameter_file

            plant = load_parameter_file(args.params)
        return SimRig(plant, seed=args.seed, paced=not args.fast)
    from hframe_id.rig.serial_rig import SerialRig

    if args.port is None:
        raise OptionError("--rig serial needs --port (e.g. /dev/ttyACM0)")
    if args.fast or args.params is not None or args.plant is not None:
        raise OptionError("--fast, --params and --plant are for --rig sim")
    return SerialRig(
        args.port,
        baudrate=args.baudrate,
        watchdog_ms=args.watchdog_ms,
        link_timeout_s=args.link_timeout,
    )


def _progress_display(stream):
    def show(done: int, planned: int, lost: int) -> None:
        width = 30
        filled = int(width * min(done, planned) / max(planned, 1))
        stream.write(
            f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{planned} samples, lost {lost}"
        )
        if done >= planned:
            stream.write("\n")
        stream.flush()

    return show


def clamped(table, names: tuple[str, ...], low: float, high: float) -> list[dict]:
    """Per input whose commanded voltages leave the DAC range [low, high] V: its name, the
    requested extreme and the samples the rig clamps."""
    import numpy as np

    found = []
    for j, name in enumerate(names):
        outside = (table[:, j] < low) | (table[:, j] > high)
        if outside.any():
            worst = table[outside, j][np.argmax(np.abs(table[outside, j]))]
            found.append(
                {
                    "input": name,
                    "requested_V": float(worst),
                    "applied_V": float(np.clip(worst, low, high)),
                    "samples": int(outside.sum()),
                }
            )
    return found


def _clamp_sentence(clamp: dict, low: float, high: float) -> str:
    return (
        f"{clamp['input']} asks for {clamp['requested_V']:g} V, outside the DAC range "
        f"[{low:g}, {high:g}] V: clamped to {clamp['applied_V']:g} V in {clamp['samples']} "
        "sample(s)"
    )


def _check_multisine(args: argparse.Namespace, period_s: float) -> None:
    """The multisine's options agree with the rig's sample period and the record: its
    components are laid out over one --period (which must fit in --duration after the
    pre-roll) and lie below the Nyquist frequency (higher ones would alias)."""
    check_length(args.period, period_s, "--period")
    nyquist_hz = 0.5 / period_s
    if args.band[1] >= nyquist_hz:
        raise OptionError(
            f"--band: {args.band[1]:g} Hz reaches the Nyquist frequency {nyquist_hz:g} Hz of the "
            f"rig's {period_s * 1e3:g} ms sample period; give F_MAX below it"
        )
    if args.duration is not None and args.duration < args.pre_roll + args.period:
        raise OptionError(
            f"--duration {args.duration:g} s is shorter than the pre-roll {args.pre_roll:g} s "
            f"+ one --period {args.period:g} s of the multisine"
        )


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id record``: the protocol on the rig, recorded to ``--out``.

    Exit status 0 if the run completed, 1 if it was aborted (the recording is kept).
    """
    check_file(args.out, "--out", args.force, make_parents=True)
    from hframe_id.recordings.log_format import PROTOCOL_ATTACHMENT
    from hframe_id.recordings.writer import Attachment
    from hframe_id.rig.logger import RunOptions, run_experiment

    rig = make_rig(args)
    try:
        period = rig.info.sample_period_s
        if args.protocol == "multisine":
            _check_multisine(args, period)
        protocol = _protocol(args, len(rig.info.inputs))
        duration = protocol.duration_s
        if duration is None:  # a sequence: its last row plus one sample
            duration = protocol.time_s[-1] + period
        check_length(duration, period, "--duration" if args.duration else f"--{args.protocol}")
        low, high = rig.info.sensors.dac_min_v, rig.info.sensors.dac_max_v
        clamps = clamped(protocol.table(period), rig.info.inputs, low, high)
        for clamp in clamps:
            print(f"hframe-id: warning: {_clamp_sentence(clamp, low, high)}", file=sys.stderr)
        attachments = []
        if args.protocol == "csv":
            attachments.append(
                Attachment(PROTOCOL_ATTACHMENT, "text/csv", Path(args.csv).read_bytes())
            )
        show = None if args.quiet or not sys.stderr.isatty() else _progress_display(sys.stderr)
        summary = run_experiment(
            rig,
            protocol,
            RunOptions(
                out=args.out,
                operator=args.operator,
                overwrite=args.force,
                progress=show,
                notes=args.notes,
            ),
            attachments,
        )
    finally:
        rig.close()
    if show is not None and summary.samples < summary.planned_samples:
        sys.stderr.write("\n")
    planned = summary.planned_samples
    lost_share = (planned - summary.samples) / planned if planned else 0.0
    if args.json:
        emit(
            "record",
            {
                **{f.name: getattr(summary, f.name) for f in dataclasses.fields(summary)},
                "lost_share": lost_share,
                "events": [{"kind": k, "reason": r} for k, r in summary.events],
                "clamped": clamps,
            },
        )
        return 1 if summary.aborted else 0
    lines = summary.lines()
    if summary.samples < planned:
        lines.append(f"not recorded   {100 * lost_share:.1f} % of the planned samples")
    lines += [f"clamped        {_clamp_sentence(clamp, low, high)}" for clamp in clamps]
    print("\n".join(lines))
    return 1 if summary.aborted else 0
