"""``hframe-id inspect``: metadata, channels, duration and data quality of a recording."""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hframe_id.cli.json_output import emit
from hframe_id.cli.outputs import add_force_option, check_file, written_together

if TYPE_CHECKING:  # the reader (NumPy, MCAP) is imported when a file is inspected
    from hframe_id.recordings.recording import Recording

#: Status fields of the last /rig/status message shown on the ``link`` line.
LINK_FIELDS = (
    "crc_errors",
    "late_commands",
    "watchdog",
    "host_period_jitter_us",
    "host_latency_max_us",
)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``inspect`` subcommand."""
    parser = subparsers.add_parser(
        "inspect",
        help="show what a recording holds and how good its data is",
        description="Print the metadata, channels with their units, duration and data quality "
        "(samples kept of those planned, lost samples, sensor validity, events) of an MCAP "
        "recording of any rig; --plot draws every input, output and extra signal.",
    )
    parser.add_argument("recording", type=Path, help="an .mcap recording (or a .partial one)")
    parser.add_argument(
        "--plot",
        nargs="?",
        const=True,
        default=None,
        metavar="PNG",
        help="draw inputs, outputs and signals to a PNG (default: the recording's name with .png)",
    )
    add_force_option(parser)
    parser.add_argument(
        "--json", action="store_true", help="print one JSON object (docs/cli-json.md)"
    )
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Run ``hframe-id inspect``: the recording's summary as text or JSON, plotted if asked."""
    from hframe_id.recordings.reader import read_log, read_recording

    target = None
    if args.plot is not None:
        target = args.recording.with_suffix(".png") if args.plot is True else Path(args.plot)
        check_file(target, "--plot", args.force, make_parents=True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        recording = read_recording(args.recording)
    log = read_log(args.recording)
    summary = summarize(recording, log)
    summary["warnings"] = [" ".join(str(w.message).split()) for w in caught]
    summary["plot"] = None
    if target is not None:
        with written_together() as staging:
            plot(recording, staging.file(target))
        summary["plot"] = str(target)
    if args.json:
        emit("inspect", summary)
        return 0
    print("\n".join(describe(summary)))
    return 0


def _range(values) -> dict[str, float | None]:
    import numpy as np

    finite = values[np.isfinite(values)]
    if not finite.size:
        return {"min": None, "max": None}
    return {"min": float(finite.min()), "max": float(finite.max())}


def summarize(recording: Recording, log) -> dict[str, Any]:
    """What ``inspect`` reports, as plain data (the ``--json`` object without its envelope)."""
    import numpy as np

    from hframe_id.recordings import log_format as fmt
    from hframe_id.recordings.completeness import completeness

    periods = np.diff(recording.time_s)
    state = completeness(recording)
    outputs = []
    for j, (name, unit) in enumerate(
        zip(recording.output_names, recording.output_units, strict=True)
    ):
        valid = recording.valid[:, j]
        first = int(np.argmax(~valid)) if not valid.all() else None
        outputs.append(
            {
                "name": name,
                "unit": unit,
                **_range(recording.outputs[:, j]),
                "valid_share": float(valid.mean()) if valid.size else 1.0,
                "first_invalid_s": None if first is None else float(recording.time_s[first]),
            }
        )
    statuses = log.decoded(fmt.STATUS_TOPIC)
    return {
        "file": str(log.path),
        "bytes": log.bytes_total,
        "finished": log.complete,
        "salvage_problem": None if log.complete else log.problem,
        "format_version": recording.experiment.get("format_version"),
        "written_by": log.library or None,
        "variant": recording.variant,
        "rig": dict(recording.rig),
        "experiment": dict(recording.experiment),
        "attachments": [
            {"name": a.name, "media_type": a.media_type, "bytes": len(a.data)}
            for a in log.attachments.values()
        ],
        "channels": [
            {
                "topic": c.topic,
                "schema": log.schemas[c.schema_id].name if c.schema_id in log.schemas else None,
                "encoding": c.message_encoding,
                "messages": len(log.messages.get(c.topic, [])),
            }
            for c in sorted(log.channels.values(), key=lambda c: c.id)
        ],
        "duration_s": recording.duration_s,
        "samples": recording.n_samples,
        "sample_period_s": recording.sample_period_s,
        "timing": {
            "period_mean_s": float(periods.mean()),
            "period_min_s": float(periods.min()),
            "period_max_s": float(periods.max()),
        }
        if periods.size
        else None,
        "completeness": {
            "planned": state.planned,
            "samples": state.samples,
            "missing": state.missing,
            "lost_share": state.lost_share,
            "lost_in_gaps": state.lost_in_gaps,
            "gaps": [list(gap) for gap in recording.sequence_gaps],
            "truncated": state.truncated,
            "aborted": state.aborted,
            "statement": state.statement(),
        },
        "inputs": [
            {"name": name, "unit": unit, **_range(recording.inputs[:, i])}
            for i, (name, unit) in enumerate(
                zip(recording.input_names, recording.input_units, strict=True)
            )
        ],
        "outputs": outputs,
        "signals": [
            {"name": name, "unit": unit, **_range(recording.signals[:, k])}
            for k, (name, unit) in enumerate(
                zip(recording.signal_names, recording.signal_units, strict=True)
            )
        ],
        "link": {k: statuses[-1].get(k) for k in LINK_FIELDS} if statuses else None,
        "events": [
            {
                "time_s": e["device_time_us"] * 1e-6
                if isinstance(e.get("device_time_us"), int)
                else None,
                "kind": e["kind"],
                "reason": e["reason"],
            }
            for e in recording.events
        ],
    }


def _value(value: Any) -> str:
    """A metadata or status value for people: floats to 4 significant digits."""
    if isinstance(value, bool) or value is None:
        return str(value)
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _between(channel: dict[str, Any]) -> str:
    if channel["min"] is None:
        return "no finite value"
    return f"{channel['min']:.4g} to {channel['max']:.4g}"


def describe(summary: dict[str, Any]) -> list[str]:
    """The human-readable lines of ``summarize``'s result."""
    state = (
        "finished" if summary["finished"] else f"UNFINISHED, salvaged: {summary['salvage_problem']}"
    )
    lines = [f"warning: {warning}" for warning in summary["warnings"]]
    lines += [
        f"file           {summary['file']} ({summary['bytes']} bytes, {state})",
        f"format         {summary['format_version']}, written by "
        f"{summary['written_by'] or 'unknown'}",
    ]
    for name in ("rig", "experiment"):
        pairs = ", ".join(f"{k}={_value(v)}" for k, v in summary[name].items())
        lines.append(f"{name:<15}{pairs}")
    for a in summary["attachments"]:
        lines.append(f"attachment     {a['name']} ({a['media_type']}, {a['bytes']} bytes)")
    for c in summary["channels"]:
        lines.append(
            f"channel        {c['topic']:<12} {c['schema'] or '-':<22} {c['encoding']} "
            f"{c['messages']} messages"
        )
    lines.append(
        f"duration       {summary['duration_s']:.3f} s, {summary['samples']} samples at "
        f"{summary['sample_period_s'] * 1e3:g} ms"
    )
    if timing := summary["timing"]:
        lines.append(
            f"timing         device period mean {timing['period_mean_s'] * 1e3:.4f} ms, "
            f"min {timing['period_min_s'] * 1e3:.4f} ms, max {timing['period_max_s'] * 1e3:.4f} ms"
        )
    done = summary["completeness"]
    if done["statement"]:
        lines.append(f"recorded       {done['statement']}")
    elif done["planned"] is not None:
        lines.append(f"recorded       {done['samples']} of {done['planned']} planned samples")
    gaps = done["gaps"]
    gap_text = ", ".join(f"{m} before sample {p}" for p, m in gaps[:5])
    lines.append(
        f"lost samples   {done['lost_in_gaps']} in {len(gaps)} gap(s)"
        + (f": {gap_text}{' ...' if len(gaps) > 5 else ''}" if gaps else "")
    )
    for kind in ("inputs", "outputs", "signals"):
        for channel in summary[kind]:
            line = f"{kind[:-1]:<15}{channel['name']} [{channel['unit']}]: {_between(channel)}"
            if kind == "outputs":
                line += f", valid {100 * channel['valid_share']:.1f} %"
                if channel["first_invalid_s"] is not None:
                    line += f" (first invalid at {channel['first_invalid_s']:.3f} s)"
            lines.append(line)
    lines.append("aborted        " + ("yes" if done["aborted"] else "no"))
    if summary["link"]:
        pairs = ", ".join(f"{k}={_value(v)}" for k, v in summary["link"].items())
        lines.append(f"link           {pairs}")
    for e in summary["events"]:
        when = "-" if e["time_s"] is None else f"{e['time_s']:.3f} s"
        lines.append(f"event          {when:>9} {e['kind']}: {e['reason']}")
    if summary["plot"]:
        lines.append(f"plot           {summary['plot']}")
    return lines


def plot(recording: Recording, target: Path) -> None:
    """Every input, output and extra signal against time, one panel per kind and unit;
    outputs past their sensor's range dotted, signals dashed."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    panels: dict[tuple[str, str], list[tuple[str, Any, Any, str]]] = {}
    for i, (name, unit) in enumerate(
        zip(recording.input_names, recording.input_units, strict=True)
    ):
        panels.setdefault(("input", unit), []).append((name, recording.inputs[:, i], None, "-"))
    for j, (name, unit) in enumerate(
        zip(recording.output_names, recording.output_units, strict=True)
    ):
        panels.setdefault(("output", unit), []).append(
            (name, recording.outputs[:, j], recording.valid[:, j], "-")
        )
    for k, (name, unit) in enumerate(
        zip(recording.signal_names, recording.signal_units, strict=True)
    ):
        panels.setdefault(("output", unit), []).append(
            (f"{name} (signal)", recording.signals[:, k], None, "--")
        )
    figure = Figure(figsize=(8, 2.2 * len(panels) + 0.8))
    FigureCanvasAgg(figure)
    axes = np.atleast_1d(figure.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0])
    t = recording.time_s
    for ax, ((kind, unit), series) in zip(axes, panels.items(), strict=True):
        for name, values, valid, style in series:
            if valid is None or valid.all():
                ax.plot(t, values, style, lw=1, label=name)
                continue
            (line,) = ax.plot(t, np.where(valid, values, np.nan), style, lw=1, label=name)
            ax.plot(t, np.where(valid, np.nan, values), ":", color=line.get_color(),
                    label=f"{name} (invalid)")  # fmt: skip
        ax.set_ylabel(f"{kind} [{unit}]")
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    figure.suptitle(recording.name())
    figure.tight_layout()
    figure.savefig(target, format="png", dpi=100)  # whatever the name ends with
