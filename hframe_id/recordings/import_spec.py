"""What to import from a CSV or MATLAB log, and how: ``ColumnMap`` (one mapped column) and
``ImportSpec`` (all of it), validated when built so that a bad command line fails before any
file is read. ``hframe_id.recordings.importer`` carries it out.
"""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from hframe_id.errors import OptionError
from hframe_id.recordings import log_format as fmt
from hframe_id.recordings.channels import Channels
from hframe_id.recordings.matrix_columns import parse_matrix_column
from hframe_id.recordings.units import COUNTS, Unit, to_si

#: What a mapped column can be.
ROLES = ("time", "input", "output", "signal")
#: Metadata keys the importer writes itself (``--rig`` / ``--experiment`` may not set them).
RIG_KEYS = frozenset(
    fmt.SIGNAL_RIG_REQUIRED
    + ("name", "signals", "signal_units", "output_validity", "encoder_counts_per_rev")
)
EXPERIMENT_KEYS = frozenset(
    fmt.EXPERIMENT_REQUIRED
    + ("description", "citation", "source.file", "source.format", "source.sha256", "source.map")
)


@dataclass(frozen=True)
class ColumnMap:
    """One mapped column: ``SOURCE=ROLE:UNIT[:NAME]`` on the command line.

    Attributes
    ----------
    source : column (CSV) or variable (.mat) name in the file, or a column of a .mat matrix:
        ``data(:,3)`` (MATLAB, 1-based) or ``data[:,2]`` (NumPy, 0-based).
    role : ``time``, ``input``, ``output`` or ``signal`` (recorded, not a model input/output).
    unit : its unit in the file (``mm``, ``deg``, ``counts``, ``ms``, ...; see ``units``).
    name : channel name in the recording (default: ``source``; required for a matrix
        column); unused for time.
    """

    source: str
    role: str
    unit: str
    name: str

    @classmethod
    def parse(cls, text: str) -> ColumnMap:
        """Parse one ``--map SOURCE=ROLE:UNIT[:NAME]`` argument; OptionError names what is wrong."""
        source, sep, spec = text.rpartition("=")
        parts = spec.split(":")
        if not sep or not source or len(parts) not in (2, 3) or not all(parts):
            raise OptionError(
                f"--map {text!r}: expected SOURCE=ROLE:UNIT or SOURCE=ROLE:UNIT:NAME, e.g. "
                "qm=output:m or 'Pos (mm)=output:mm:x'"
            )
        role, unit = parts[0], parts[1]
        if role not in ROLES:
            raise OptionError(f"--map {text!r}: role {role!r} is not one of {', '.join(ROLES)}")
        if role == "time" and len(parts) == 3:
            raise OptionError(f"--map {text!r}: the time column has no channel NAME")
        matrix = parse_matrix_column(source)
        if matrix is not None and matrix.problem:
            raise OptionError(f"--map {text!r}: {matrix.problem}")
        if matrix is not None and role != "time" and len(parts) == 2:
            raise OptionError(
                f"--map {text!r}: a matrix column needs a channel NAME, e.g. "
                f"{source}={role}:{unit}:{'u' if role == 'input' else 'y'}"
            )
        return cls(source, role, unit, parts[2] if len(parts) == 3 else source)

    def __str__(self) -> str:
        text = f"{self.source}={self.role}:{self.unit}"
        return text if self.name == self.source else f"{text}:{self.name}"


@dataclass(frozen=True)
class ImportSpec:
    """What to import and how; validated on construction (``OptionError``).

    Attributes
    ----------
    columns : mapped columns: at most one time column, at least one input and one output.
    variant : model variant name of the rig (letters, digits, '-', '_').
    sample_period_s : nominal sample period [s]; needed without a time column (samples at
        k * period), else the median time step by default.
    counts_per_rev : encoder counts per revolution, for columns in ``counts``.
    noise_std : per output channel, its sensor noise std as ``"VALUE"`` (in the channel's SI
        unit), ``"VALUE:UNIT"`` or ``"estimate"``.
    nan_invalid : outputs whose missing values (empty, NaN, inf) are marked invalid instead
        of being an error.
    rig_name : the rig's name (``rig.name``).
    rig, experiment : further metadata (keys the importer writes itself are refused).
    description, citation : what the experiment was; where the data come from.
    operator : who ran the experiment; protocol : what kind of experiment it was.
    start_time : when sample 0 was taken (time-zone aware); None: unknown (written empty,
        message times count from the Unix epoch).
    """

    columns: tuple[ColumnMap, ...]
    variant: str
    sample_period_s: float | None = None
    counts_per_rev: float | None = None
    noise_std: Mapping[str, str] = field(default_factory=dict)
    nan_invalid: tuple[str, ...] = ()
    rig_name: str = ""
    rig: Mapping[str, str] = field(default_factory=dict)
    experiment: Mapping[str, str] = field(default_factory=dict)
    description: str = ""
    citation: str = ""
    operator: str = "unknown"
    protocol: str = "external"
    start_time: dt.datetime | None = None

    def __post_init__(self) -> None:
        if not fmt.VARIANT_PATTERN.match(self.variant):
            raise OptionError(
                f"--variant {self.variant!r}: a model variant name has letters, digits, "
                "'-' and '_' only"
            )
        roles = [c.role for c in self.columns]
        if roles.count("time") > 1:
            raise OptionError("--map: more than one time column")
        for role in ("input", "output"):
            if role not in roles:
                raise OptionError(f"--map: no {role} column (e.g. --map COLUMN={role}:UNIT)")
        if "time" not in roles and self.sample_period_s is None:
            raise OptionError("give --sample-period SECONDS or a time column (--map t=time:s)")
        period = self.sample_period_s
        if period is not None and not (math.isfinite(period) and period >= 1e-6):
            raise OptionError(
                f"--sample-period must be finite and >= 1e-6 s (the log's clock counts "
                f"microseconds), got {period}"
            )
        counts = self.counts_per_rev
        if counts is not None and not (math.isfinite(counts) and counts > 0):
            raise OptionError(f"--counts-per-rev must be finite and > 0, got {counts}")
        for column in self.columns:
            unit = self.unit(column)
            if column.role == "time" and unit.si != "s":
                raise OptionError(f"--map {column}: a time column needs a time unit (s, ms, us)")
        outputs = self.names("output")
        for option, names in (("--nan-invalid", self.nan_invalid), ("--noise-std", self.noise_std)):
            stray = [n for n in names if n not in outputs]
            if stray:
                raise OptionError(
                    f"{option} {', '.join(stray)}: not an output channel ({', '.join(outputs)})"
                )
        for option, given, own in (
            ("--rig", self.rig, RIG_KEYS),
            ("--experiment", self.experiment, EXPERIMENT_KEYS),
        ):
            taken = [k for k in given if k in own or k.startswith(fmt.NOISE_STD_PREFIX)]
            if taken:
                raise OptionError(
                    f"{option} {', '.join(taken)}: set by import itself (use its own option)"
                )
        if self.start_time is not None and self.start_time.tzinfo is None:
            raise OptionError("--start-time must carry a time zone (e.g. +00:00)")

    def unit(self, column: ColumnMap) -> Unit:
        """The column's unit as SI unit and factor."""
        try:
            return to_si(column.unit, self.counts_per_rev)
        except ValueError as err:
            hint = " (give --counts-per-rev)" if column.unit == COUNTS else ""
            raise OptionError(f"--map {column}: {err}{hint}") from None

    def names(self, role: str) -> tuple[str, ...]:
        """Channel names of the mapped columns with ``role``, in command-line order."""
        return tuple(c.name for c in self.columns if c.role == role)

    def channels(self) -> Channels:
        """The channel declaration (names and SI units per role) the mapped columns make."""

        def units(role: str) -> tuple[str, ...]:
            return tuple(self.unit(c).si for c in self.columns if c.role == role)

        try:
            return Channels(
                inputs=self.names("input"),
                input_units=units("input"),
                outputs=self.names("output"),
                output_units=units("output"),
                signals=self.names("signal"),
                signal_units=units("signal"),
                validity=tuple(n for n in self.names("output") if n in self.nan_invalid),
            )
        except ValueError as err:
            raise OptionError(f"--map: {err}") from None

    def noise_std_si(self) -> dict[str, float | str]:
        """``noise_std`` in each output's SI unit (or ``"estimate"``)."""
        si = {c.name: self.unit(c).si for c in self.columns if c.role == "output"}
        out: dict[str, float | str] = {}
        for name, text in self.noise_std.items():
            value, _, unit_name = text.partition(":")
            try:
                if value == fmt.NOISE_ESTIMATE and not unit_name:
                    out[name] = fmt.NOISE_ESTIMATE
                    continue
                unit = to_si(unit_name, self.counts_per_rev) if unit_name else Unit(si[name], 1)
                if unit.si != si[name]:
                    raise ValueError(f"unit {unit_name!r} is not a unit of {si[name]}")
                out[name] = fmt.parse_noise_std(unit.factor * float(value))
            except ValueError as err:
                raise OptionError(
                    f"--noise-std {name}={text}: {err} (VALUE, VALUE:UNIT or {fmt.NOISE_ESTIMATE})"
                ) from None
        return out
