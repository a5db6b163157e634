"""``hframe-id inspect``: metadata, channels, duration and data quality of a recording."""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

from hframe_id.cli.outputs import check_file

if TYPE_CHECKING:  # the reader (NumPy, MCAP) is imported when a file is inspected
    from hframe_id.recordings.recording import Recording


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "inspect",
        help="show what a recording holds and how good its data is",
        description="Print the metadata, channels, duration and data quality (lost samples, "
        "laser validity, events) of an MCAP recording; --plot draws its signals.",
    )
    parser.add_argument("recording", type=Path, help="an .mcap recording (or a .partial one)")
    parser.add_argument(
        "--plot",
        nargs="?",
        const=True,
        default=None,
        metavar="PNG",
        help="draw inputs and outputs to a PNG (default: the recording's name with .png)",
    )
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from hframe_id.recordings.reader import read_log, read_recording

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        recording = read_recording(args.recording)
    log = read_log(args.recording)
    for warning in caught:
        print(f"warning: {warning.message}")
    for line in describe(recording, log):
        print(line)
    if args.plot is not None:
        target = args.recording.with_suffix(".png") if args.plot is True else Path(args.plot)
        check_file(target, "--plot", make_parents=True)
        plot(recording, target)
        print(f"plot           {target}")
    return 0


def describe(recording: Recording, log) -> list[str]:
    import numpy as np

    from hframe_id.recordings import log_format as fmt

    state = "finished" if log.complete else f"UNFINISHED, salvaged ({log.problem})"
    lines = [
        f"file           {log.path} ({log.bytes_total} bytes, {state})",
        f"format         {recording.experiment.get('format_version')}, written by "
        f"{log.library or 'unknown'}",
    ]
    for name in ("rig", "experiment"):
        raw = log.metadata.get(name, {})
        lines.append(f"{name:<15}" + ", ".join(f"{k}={v}" for k, v in raw.items()))
    for attachment in log.attachments.values():
        lines.append(
            f"attachment     {attachment.name} ({attachment.media_type}, "
            f"{len(attachment.data)} bytes)"
        )
    for channel in sorted(log.channels.values(), key=lambda c: c.id):
        schema = log.schemas.get(channel.schema_id)
        count = len(log.messages.get(channel.topic, []))
        lines.append(
            f"channel        {channel.topic:<12} {schema.name if schema else '-':<22} "
            f"{channel.message_encoding} {count} messages"
        )
    n = recording.n_samples
    lost = sum(m for _, m in recording.sequence_gaps)
    lines.append(
        f"duration       {recording.duration_s:.3f} s, {n} samples at "
        f"{recording.sample_period_s * 1e3:g} ms"
    )
    periods = np.diff(recording.time_s)
    if periods.size:
        lines.append(
            f"timing         device period mean {periods.mean() * 1e3:.4f} ms, "
            f"min {periods.min() * 1e3:.4f} ms, max {periods.max() * 1e3:.4f} ms"
        )
    gap_text = ", ".join(f"{m} before sample {p}" for p, m in recording.sequence_gaps[:5])
    more = " ..." if len(recording.sequence_gaps) > 5 else ""
    lines.append(
        f"lost samples   {lost} in {len(recording.sequence_gaps)} gap(s)"
        + (f": {gap_text}{more}" if gap_text else "")
    )
    for j, name in enumerate(recording.output_names):
        valid = recording.valid[:, j]
        if not valid.all():
            first = int(np.argmax(~valid))
            lines.append(
                f"valid          {name}: {valid.mean() * 100:.1f} % of samples "
                f"(first invalid at {recording.time_s[first]:.3f} s)"
            )
        else:
            lines.append(f"valid          {name}: 100 %")
    lines.append("aborted        " + ("yes" if recording.aborted else "no"))
    statuses = log.decoded(fmt.STATUS_TOPIC)
    if statuses:
        last = statuses[-1]
        lines.append(
            "link           "
            + ", ".join(
                f"{k}={last[k]}"
                for k in (
                    "crc_errors",
                    "late_commands",
                    "watchdog",
                    "host_period_jitter_us",
                    "host_latency_max_us",
                )
            )
        )
    for event in recording.events:
        t = event.get("device_time_us")
        when = f"{t * 1e-6:.3f} s" if isinstance(t, int) else "-"
        lines.append(f"event          {when:>9} {event['kind']}: {event['reason']}")
    return lines


def plot(recording: Recording, target: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    kinds = [("u [V]", [(n, recording.inputs[:, i]) for i, n in enumerate(recording.input_names)])]
    angles = [
        (n, recording.outputs[:, j])
        for j, n in enumerate(recording.output_names)
        if n.startswith("phi")
    ]
    positions = [j for j, n in enumerate(recording.output_names) if n in ("x", "y")]
    if angles:
        kinds.append(("motor angle [rad]", angles))
    fig, axes = plt.subplots(
        len(kinds) + (1 if positions else 0), 1, sharex=True, figsize=(8, 2.4 * (len(kinds) + 1))
    )
    axes = np.atleast_1d(axes)
    t = recording.time_s
    for ax, (label, series) in zip(axes, kinds, strict=False):
        for name, values in series:
            ax.plot(t, values, label=name)
        ax.set_ylabel(label)
        ax.legend(loc="best")
    if positions:
        ax = axes[-1]
        for j in positions:
            name = recording.output_names[j]
            values = recording.outputs[:, j]
            (line,) = ax.plot(t, np.where(recording.valid[:, j], values, np.nan), label=name)
            ax.plot(
                t,
                np.where(recording.valid[:, j], np.nan, values),
                ":",
                color=line.get_color(),
                label=f"{name} (held, past range)",
            )
        ax.set_ylabel("laser position [m]")
        ax.legend(loc="best")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(recording.name())
    fig.tight_layout()
    target.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(target, dpi=100)
    plt.close(fig)
