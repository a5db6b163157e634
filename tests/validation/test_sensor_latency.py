"""A fit's sensor latencies are replayed by ``validate`` as the fit compared them (issue 25,
item 1: what the fit reports is what ``validate`` reproduces with the written file). A fit
with ``--latency phi1=1 --latency x=3`` wrote its file with the latencies in its provenance;
``validate`` compared the channels unshifted and showed 0.0070 rad where the fit's
residuals were 6e-5 rad."""

import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from hframe_id.cli import main
from hframe_id.recordings.reader import read_recording
from hframe_id.resources import datasets_dir
from hframe_id.validation import ValidationOptions, validate
from hframe_id.validation.output import to_document
from tests.cli.refusals import refused
from tests.validation.test_validation import ROOT, TABLE, _steps, noisy_recording

LATE = 2  # samples the phi1 encoder lags in the late record


def _records():
    """A record of Table 4.2, and the same record with its phi1 encoder reporting each sample
    ``LATE`` samples late (the record starts at rest: its first samples repeat the rest)."""
    rec = noisy_recording(TABLE, _steps(-4.0, 2.5), seed=3, name="late.mcap")
    outputs = rec.outputs.copy()
    outputs[LATE:, 0] = rec.outputs[:-LATE, 0]
    return rec, replace(rec, outputs=outputs)


def test_a_files_latency_is_applied_and_reported():
    on_time, late_record = _records()
    fitted = replace(TABLE, provenance={"fit_options": {"latency_samples": {"phi1": LATE}}})
    result = validate([TABLE, fitted], [late_record], ValidationOptions(horizon=0))
    plain, late = (run.channels[0] for run in result.recordings[0].runs)
    reference = validate([TABLE], [on_time], ValidationOptions(horizon=0))
    on_time_rms = reference.recordings[0].runs[0].channels[0].residual_rms
    assert plain.name == late.name == "phi1"
    # With the latency the late record replays as the on-time one does (the same noise,
    # LATE samples fewer: within 5 %); without it, the 2 ms lag of a motor turning at tens
    # of rad/s is 100s of times the noise.
    assert abs(late.residual_rms / on_time_rms - 1) < 0.05
    assert plain.residual_rms > 100 * on_time_rms
    assert late.valid_samples == plain.valid_samples - LATE
    document = to_document(result)
    assert [f["latency_samples"] for f in document["parameter_files"]] == [{}, {"phi1": LATE}]


def test_a_latency_that_is_not_whole_samples_is_one_line(tmp_path, capsys):
    doc = yaml.safe_load((ROOT / "models" / "hframe-8-table4.2.yaml").read_text())
    doc["provenance"] = {"fit_options": {"latency_samples": {"phi1": -1}}}
    path = tmp_path / "late.yaml"
    path.write_text(yaml.safe_dump(doc))
    refused(["validate", path, "4V_xmotion.mcap"], capsys, path, "latency_samples", "-1")


def test_validate_prints_the_latency_it_applied(tmp_path, capsys):
    doc = yaml.safe_load((ROOT / "models" / "hframe-8-table4.2.yaml").read_text())
    doc["provenance"] = {"fit_options": {"latency_samples": {"x": 3}}}
    path = tmp_path / "late.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert main(["validate", str(path), "4V_xmotion.mcap", "--horizon", "0", "--quiet"]) == 0
    assert "late.yaml: sensor latency as fitted, x 3 sample(s)" in capsys.readouterr().out


def _late_laser_record(tmp_path) -> Path:
    """The shipped 4 V x-motion record with its laser x reporting ``LATE`` samples late,
    imported as a user's own log would be (CSV, ``hframe-id import``; the shipped rig's
    sensor noise levels)."""
    rec = read_recording(datasets_dir() / "4V_xmotion.mcap")
    outputs = rec.outputs.copy()
    j = list(rec.output_names).index("x")
    outputs[LATE:, j] = rec.outputs[:-LATE, j]
    names = ["t", *rec.input_names, *rec.output_names]
    csv = tmp_path / "late.csv"
    table = np.column_stack([rec.time_s, rec.inputs, outputs])
    np.savetxt(csv, table, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    columns = [f"--map={n}={role}:{unit}" for n, role, unit in _ROLES]
    noise = [f"--noise-std={n}={std}" for n, std in (("phi1", 5.65e-6), ("phi2", 5.65e-6))]
    noise += [f"--noise-std={n}=5e-6" for n in ("x", "y")]
    out = tmp_path / "late.mcap"
    argv = ["import", str(csv), "--variant", "hframe-8", *columns, *noise, "--out", str(out)]
    assert main([*argv, "--quiet"]) == 0
    return out


_ROLES = (
    ("t", "time", "s"),
    ("u1", "input", "V"),
    ("u2", "input", "V"),
    ("phi1", "output", "rad"),
    ("phi2", "output", "rad"),
    ("x", "output", "m"),
    ("y", "output", "m"),
)


@pytest.mark.integration
def test_the_fit_report_shows_the_residuals_validate_replays(tmp_path, capsys):
    """The report's "RMS residual" of each channel is what ``validate`` shows for the
    written file (both to the report's three digits), on a record whose laser is late."""
    record = str(_late_laser_record(tmp_path))
    argv = ["fit", record, "--latency", f"x={LATE}", "--no-cross-validation", "--no-plots"]
    assert main([*argv, "--json", "--quiet", "--out-dir", str(tmp_path / "fit")]) == 0
    summary = json.loads(capsys.readouterr().out)
    report = Path(summary["report"]).read_text()
    shown = re.search(r"RMS residual: (.*)", report).group(1)
    assert f"(sensor {LATE} samples late)" in shown
    assert main(["validate", summary["parameter_file"], record, "--json", "--quiet"]) == 0
    replayed = json.loads(capsys.readouterr().out)["recordings"][0]["results"][0]["channels"]
    scale = {"rad": 1.0, "m": 1e3}  # the report shows lengths in mm
    for channel in replayed:
        value = f"{scale[channel['unit']] * channel['residual_rms']:.3g}"
        assert f"{channel['name']} {value} " in shown, (channel, shown)
    # The late laser is followed to its noise (5e-6 m), as the fit saw it: unshifted, a
    # channel 2 ms late in a 4 V x motion would miss by far more.
    assert next(c for c in replayed if c["name"] == "x")["residual_rms"] < 2e-5
