"""Batch manifests: which fits to run (rig, time of the run, recordings, model, start, free set).

A manifest is YAML::

    format_version: '1.0'
    defaults: {model: hframe-8, initial: ../models/hframe-8-table4.2.yaml}   # optional
    fits:
      - rig: rig-01
        time: '2026-01-05T08:00:00+00:00'
        recordings: [rig-01/week-00-y.mcap, rig-01/week-00-x.mcap]
        free: [k_*, g_2]                                                   # optional

or CSV with a header ``rig,time,recordings,model,initial,free`` (``recordings`` separated by
``;``, ``free`` by ``,``). Paths are relative to the manifest's folder (resolved to absolute
paths: on a cluster every worker must see the same files there). ``initial`` defaults
to the model's reference file, ``free`` to the model's default free set. Every entry is
checked before any fit starts; the first problem raises ``ManifestError`` naming the file, the
entry and the field.
"""

from __future__ import annotations

import csv
import datetime as dt
import difflib
import fnmatch
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from hframe_id.documents import load_yaml, read_text
from hframe_id.errors import HframeIdError, shown
from hframe_id.models import declaration, parameter_specs, variants
from hframe_id.parameters import load_parameter_file

FORMAT_VERSION = "1.0"
FIELDS = ("rig", "time", "recordings", "model", "initial", "free")
REQUIRED = ("rig", "time", "recordings", "model")
#: Fields a YAML manifest's ``defaults`` block may set for every entry.
DEFAULTABLE = ("model", "initial", "free")


class ManifestError(HframeIdError):
    """A batch manifest is unreadable or an entry is invalid."""


@dataclass(frozen=True)
class FitJob:
    """One fit of a batch: a rig's recordings of one run, fitted jointly.

    Attributes
    ----------
    entry : 1-based entry number in the manifest (CSV: data row number).
    rig : the rig's id.
    time : when the run was recorded (UTC).
    recordings : the recordings, resolved.
    model : model variant.
    initial : the initial parameter file, resolved.
    free : free parameter names or patterns (None: the model's default set).
    """

    entry: int
    rig: str
    time: dt.datetime
    recordings: tuple[Path, ...]
    model: str
    initial: Path
    free: tuple[str, ...] | None


def load_manifest(path: str | Path) -> list[FitJob]:
    """The manifest's fits, every entry checked (files exist, model known, start file of
    the model, free names match its parameters, time with a time zone)."""
    path = Path(path)
    try:
        text = read_text(path, "manifest", ManifestError)
    except OSError as err:
        raise ManifestError(f"{path}: cannot read the manifest ({err.strerror})") from None
    if path.suffix.lower() == ".csv":
        raw = _csv_entries(path, text)
    else:
        raw = _yaml_entries(path, text)
    if not raw:
        raise ManifestError(f"{path}: the manifest lists no fits")
    jobs = [_job(path, number, entry) for number, entry in enumerate(raw, start=1)]
    seen: dict[tuple[str, dt.datetime], int] = {}
    for job in jobs:
        other = seen.setdefault((job.rig, job.time), job.entry)
        if other != job.entry:
            raise ManifestError(
                f"{path}: entry {job.entry} (rig {job.rig}): field 'time': "
                f"{job.time.isoformat()} repeats entry {other} of the same rig"
            )
    return jobs


def _yaml_entries(path: Path, text: str) -> list[dict[str, Any]]:
    doc = load_yaml(text, str(path), ManifestError)
    if not isinstance(doc, dict) or not isinstance(doc.get("fits"), list):
        raise ManifestError(f"{path}: a manifest needs a 'fits' list")
    version = str(doc.get("format_version", ""))
    if version != FORMAT_VERSION:
        raise ManifestError(
            f"{path}: field 'format_version': expected '{FORMAT_VERSION}', got {shown(version)}"
        )
    unknown = sorted(set(doc) - {"format_version", "title", "defaults", "fits"})
    if unknown:
        raise ManifestError(f"{path}: unknown top-level field {shown(unknown[0])}")
    defaults = doc.get("defaults") or {}
    if not isinstance(defaults, dict):
        raise ManifestError(f"{path}: field 'defaults' must be a mapping")
    for key in defaults:
        if key not in DEFAULTABLE:
            raise ManifestError(
                f"{path}: defaults: field {shown(key)} cannot have a default ({_suggest(key)})"
            )
    entries = []
    for number, entry in enumerate(doc["fits"], start=1):
        if not isinstance(entry, dict):
            raise ManifestError(f"{path}: entry {number}: must be a mapping, got {shown(entry)}")
        entries.append({**defaults, **entry})
    return entries


def _csv_entries(path: Path, text: str) -> list[dict[str, Any]]:
    reader = csv.DictReader(text.splitlines())
    try:
        rows = list(reader)
    except csv.Error as err:  # a cell beyond the csv module's 128 kB limit, say
        raise ManifestError(f"{path}: not a readable CSV manifest ({err})") from None
    header = reader.fieldnames or []
    doubled = sorted({name for name in header if header.count(name) > 1})
    if doubled:  # DictReader keeps the last column of a name, silently
        raise ManifestError(f"{path}: line 1: the header has column {shown(doubled[0])} twice")
    entries = []
    for row in rows:
        if None in row:
            raise ManifestError(f"{path}: entry {len(entries) + 1}: more cells than columns")
        entry: dict[str, Any] = {k: v.strip() for k, v in row.items() if v and v.strip()}
        if "recordings" in entry:
            entry["recordings"] = [p.strip() for p in entry["recordings"].split(";") if p]
        if "free" in entry:
            entry["free"] = [p.strip() for p in entry["free"].split(",") if p.strip()]
        entries.append(entry)
    return entries


def _suggest(key: str) -> str:
    close = difflib.get_close_matches(str(key), FIELDS, n=1)
    return f"did you mean {close[0]!r}?" if close else f"fields: {', '.join(FIELDS)}"


def _job(path: Path, number: int, entry: dict[str, Any]) -> FitJob:
    rig = entry.get("rig")
    where = f"{path}: entry {number}" + (f" (rig {rig})" if rig else "")

    def fail(field: str, problem: str) -> ManifestError:
        return ManifestError(f"{where}: field {shown(field)}: {problem}")

    for key in entry:
        if key not in FIELDS:
            raise ManifestError(f"{where}: unknown field {shown(key)} ({_suggest(key)})")
    for key in REQUIRED:
        if key not in entry or entry[key] in (None, "", []):
            raise fail(key, "missing")
    if not isinstance(rig, str | int) or isinstance(rig, bool):
        raise fail("rig", f"must be a name, got {shown(rig)}")
    time = _time(entry["time"], fail)
    model = entry["model"]
    if model not in variants():
        raise fail("model", f"unknown model {shown(model)} (known: {', '.join(variants())})")
    folder = path.parent.resolve()
    recordings = entry["recordings"]
    if isinstance(recordings, str):
        recordings = [recordings]
    if not isinstance(recordings, list) or not all(isinstance(p, str) for p in recordings):
        raise fail("recordings", f"must be a list of files, got {shown(recordings)}")
    resolved = tuple(folder / p for p in recordings)
    for original, file in zip(recordings, resolved, strict=True):
        if not file.is_file():
            raise fail("recordings", f"{original}: no such file ({file})")
    if "initial" in entry:
        initial = folder / str(entry["initial"])
        if not initial.is_file():
            raise fail("initial", f"{entry['initial']}: no such file ({initial})")
    else:
        initial = declaration(model).reference_file
        if initial is None:
            raise fail("initial", f"missing (model {shown(model)} declares no reference file)")
    try:
        _check_start(initial, model)
    except HframeIdError as err:
        raise fail("initial", str(err)) from None
    return FitJob(number, str(rig), time, resolved, model, initial, _free(entry, model, fail))


@lru_cache(maxsize=64)
def _check_start(initial: Path, model: str) -> None:
    """Raises ``ParameterFileError`` unless ``initial`` is a valid parameter file of
    ``model`` (checked once per file and model)."""
    load_parameter_file(initial, variant=model)


def _time(value: Any, fail) -> dt.datetime:
    if isinstance(value, dt.datetime):
        time = value
    else:
        try:
            time = dt.datetime.fromisoformat(str(value))
        except ValueError:
            raise fail("time", f"{shown(value)} is not an ISO 8601 time") from None
    if time.tzinfo is None:
        raise fail("time", f"{value!s} lacks a time zone (e.g. +00:00)")
    return time.astimezone(dt.UTC)


def _free(entry: dict[str, Any], model: str, fail) -> tuple[str, ...] | None:
    if "free" not in entry:
        return None
    free = entry["free"]
    if isinstance(free, str):
        free = [p.strip() for p in free.split(",") if p.strip()]
    if not isinstance(free, list) or not free or not all(isinstance(p, str) for p in free):
        raise fail("free", f"must be a list of parameter names or patterns, got {shown(free)}")
    names = [spec.name for spec in parameter_specs(model)]
    for pattern in free:
        if not fnmatch.filter(names, pattern):
            close = difflib.get_close_matches(pattern, names, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise fail("free", f"{shown(pattern)} matches no parameter of {model}{hint}")
    return tuple(free)
