"""Import of CSV and MATLAB logs (hframe-id import), log format 1.1 (SignalSample), the shipped
EMPS recording."""

from __future__ import annotations

import hashlib
import math
import re
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from hframe_id.cli import main
from hframe_id.errors import LogFormatError, ModelError
from hframe_id.recordings import log_format as fmt
from hframe_id.recordings import read_recording
from hframe_id.recordings.channels import Channels
from hframe_id.recordings.writer import LogWriter

ROOT = Path(__file__).resolve().parents[2]
EMPS = ROOT / "datasets" / "real" / "emps-estimation.mcap"
EMPS_MAT = ROOT / "datasets" / "real" / "DATA_EMPS.mat"  # the source, shipped beside it
N = 200


@pytest.fixture(scope="module")
def signals() -> dict[str, np.ndarray]:
    """Seeded random columns in the units a user's logger might write."""
    rng = np.random.default_rng(10)
    return {
        "time_ms": np.arange(N) * 0.5 + 3.0,  # 2 kHz, starting at 3 ms
        "u": rng.uniform(-5, 5, N),
        "pos": np.cumsum(rng.normal(0, 0.1, N)),  # mm
        "enc": np.cumsum(rng.integers(-3, 4, N)).astype(float),  # counts
        "ref": rng.normal(0, 1e-3, N),  # m
    }


def write_csv(path: Path, columns: dict[str, list], comment: str = "") -> Path:
    """Values written with repr, so that they read back bit for bit."""
    lines = [comment] if comment else []
    lines.append(",".join(columns))
    for row in zip(*columns.values(), strict=True):
        lines.append(",".join(v if isinstance(v, str) else repr(float(v)) for v in row))
    path.write_text("\n".join(lines) + "\n")
    return path


def csv_args(ref_unit: str = "m") -> list[str]:
    return [
        "--map", "time_ms=time:ms", "--map", "u=input:V", "--map", "pos=output:mm:x",
        "--map", "enc=output:counts:phi1", "--map", f"ref=signal:{ref_unit}",
        "--counts-per-rev", "2000", "--variant", "my-axis",
    ]  # fmt: skip


CSV_ARGS = csv_args()


def run(capsys, *args: str) -> tuple[int, str]:
    code = main(["import", *map(str, args)])
    return code, capsys.readouterr().err


def test_csv_round_trip(tmp_path, signals, capsys):
    source = write_csv(tmp_path / "log.csv", {k: list(v) for k, v in signals.items()}, "# rig A")
    out = tmp_path / "run.mcap"
    code, err = run(
        capsys, source, *CSV_ARGS, "--noise-std", "x=0.002:mm", "--noise-std", "phi1=estimate",
        "--rig-name", "bench A", "--rig", "screw_lead_m=0.004", "--description", "random test",
        "--citation", "nobody, 2025", "--start-time", "2025-03-01T12:00:00+00:00", "--out", out,
    )  # fmt: skip
    assert code == 0, err
    assert "200 samples at 0.5 ms" in err
    rec = read_recording(out)
    assert rec.variant == "my-axis" and rec.sample_period_s == 0.0005
    assert rec.input_names == ("u",) and rec.input_units == ("V",)
    assert rec.output_names == ("x", "phi1") and rec.output_units == ("m", "rad")
    assert rec.signal_names == ("ref",) and rec.signal_units == ("m",)
    np.testing.assert_array_equal(rec.inputs[:, 0], signals["u"])
    np.testing.assert_array_equal(rec.outputs[:, 0], 1e-3 * signals["pos"])
    np.testing.assert_array_equal(rec.outputs[:, 1], 2 * math.pi / 2000 * signals["enc"])
    np.testing.assert_array_equal(rec.signals[:, 0], signals["ref"])
    assert rec.valid.all()
    # The log's clock counts microseconds: times are exact to 1 us.
    np.testing.assert_allclose(rec.time_s, (signals["time_ms"] - 3.0) * 1e-3, rtol=0, atol=1e-9)
    assert rec.declared_noise_std("x") == pytest.approx(2e-6, rel=1e-15)
    assert rec.declared_noise_std("phi1") == "estimate"
    assert rec.rig["name"] == "bench A" and rec.rig["screw_lead_m"] == 0.004
    assert rec.rig["encoder_counts_per_rev"] == 2000 and rec.rig["backend"] == "import"
    assert rec.experiment["format_version"] == fmt.SIGNAL_FORMAT_VERSION
    assert rec.experiment["description"] == "random test"
    assert rec.experiment["citation"] == "nobody, 2025"
    assert rec.experiment["start_time"] == "2025-03-01T12:00:00+00:00"
    assert rec.experiment["source.file"] == "log.csv"
    assert rec.experiment["source.sha256"] == hashlib.sha256(source.read_bytes()).hexdigest()
    assert rec.experiment["source.map"].startswith("time_ms=time:ms u=input:V pos=output:mm:x")
    assert list(rec.to_dataframe().columns) == [
        "u [V]", "x [m]", "x valid", "phi1 [rad]", "phi1 valid", "ref [m]",
    ]  # fmt: skip


def test_mat_round_trip(tmp_path, signals, capsys):
    source = tmp_path / "log.mat"
    scipy.io.savemat(
        source,
        {
            "vir": signals["u"].reshape(-1, 1),
            "qm": signals["ref"].reshape(1, -1),  # a row vector is a vector too
            "qg": signals["pos"].reshape(-1, 1),
            "gtau": 35.15,
            "kp": np.array([[160.18]]),
            "note": "not numeric",
            "table": np.ones((N, 2)),
        },
    )
    out = tmp_path / "sub" / "run.mcap"
    code, err = run(
        capsys, source, "--map", "vir=input:V", "--map", "qm=output:m", "--map", "qg=signal:mm",
        "--sample-period", "1e-3", "--variant", "emps-axis", "--noise-std", "qm=estimate",
        "--out", out,
    )  # fmt: skip
    assert code == 0, err
    assert "rig metadata from the file: gtau, kp" in err
    rec = read_recording(out)
    np.testing.assert_array_equal(rec.inputs[:, 0], signals["u"])
    np.testing.assert_array_equal(rec.outputs[:, 0], signals["ref"])
    np.testing.assert_array_equal(rec.signals[:, 0], 1e-3 * signals["pos"])
    np.testing.assert_array_equal(rec.time_s, np.arange(N) * 1000 * 1e-6)  # clock in us
    assert rec.rig["gtau"] == 35.15 and rec.rig["kp"] == 160.18 and "note" not in rec.rig
    assert rec.experiment["source.format"] == "mat"
    assert rec.declared_noise_std("qm") == "estimate"
    with pytest.raises(ModelError, match="no output 'vir'"):
        rec.declared_noise_std("vir")


def test_import_is_reproducible(tmp_path, signals, capsys):
    source = write_csv(tmp_path / "log.csv", {k: list(v) for k, v in signals.items()})
    first, second = tmp_path / "a.mcap", tmp_path / "b.mcap"
    assert run(capsys, source, *CSV_ARGS, "--out", first)[0] == 0
    assert run(capsys, source, *CSV_ARGS, "--out", second)[0] == 0
    assert first.read_bytes() == second.read_bytes()


def test_missing_output_values_marked_invalid_on_request(tmp_path, signals, capsys):
    columns = {k: list(v) for k, v in signals.items()}
    for i in (5, 6, 7, 50):
        columns["pos"][i] = ""
    source = write_csv(tmp_path / "gaps.csv", columns)
    out = tmp_path / "gaps.mcap"
    code, err = run(capsys, source, *CSV_ARGS, "--nan-invalid", "x", "--out", out)
    assert code == 0, err
    rec = read_recording(out)
    assert np.flatnonzero(~rec.valid[:, 0]).tolist() == [5, 6, 7, 50]
    assert np.isnan(rec.outputs[[5, 6, 7, 50], 0]).all() and rec.valid[:, 1].all()
    assert rec.rig["output_validity"] == "x"


# -- errors: one line naming file, field and value; exit 2; no output file ---------------------


def corrupt(columns: dict[str, list], column: str, index: int, value) -> dict[str, list]:
    changed = {k: list(v) for k, v in columns.items()}
    changed[column][index] = value
    return changed


@pytest.mark.parametrize(
    ("change", "args", "message"),
    [
        (None, [*CSV_ARGS, "--map", "poss=output:mm"], r"log\.csv: no column 'poss'; nearest: "
         r"'pos' \(has: time_ms, u, pos, enc, ref\)"),
        (("time_ms", 6, 2.0), CSV_ARGS, r"time column 'time_ms' must increase strictly .*"
         r"sample 6 \(line 8\) is 2 ms after 5.5 ms"),
        (("pos", 9, ""), CSV_ARGS, r"column 'pos' \(output\) has no value .* at sample 9 "
         r"\(line 11\).*--nan-invalid x"),
        (("u", 3, "nan"), [*CSV_ARGS, "--nan-invalid", "x"], r"column 'u' \(input\) has no "
         "value .*an input must have a value"),
        (("pos", 4, "abc"), CSV_ARGS, r"column 'pos', sample 4 \(line 6\): 'abc' is not a "
         "number"),
        (None, csv_args("furlong"), r"log\.csv: --map ref=signal:furlong: unknown unit "
         "'furlong'"),
        (None, csv_args("degree"), r"unknown unit 'degree' \(did you mean 'deg'\?\)"),
        (None, [*CSV_ARGS, "--nan-invalid", "u"], r"--nan-invalid u: not an output channel"),
    ],
)  # fmt: skip
def test_csv_errors(tmp_path, signals, capsys, change, args, message):
    columns = {k: list(v) for k, v in signals.items()}
    if change:
        columns = corrupt(columns, *change)
    source = write_csv(tmp_path / "log.csv", columns)
    code, err = run(capsys, source, *args, "--out", tmp_path / "out.mcap")
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("hframe-id: error: ")
    assert re.search(message, err), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv"]


def test_ragged_csv(tmp_path, capsys):
    source = tmp_path / "r.csv"
    source.write_text("t,u,y\n0,1,2\n0.001,1\n")
    maps = ["--map", "t=time:s", "--map", "u=input:V", "--map", "y=output:m"]
    code, err = run(capsys, source, *maps, "--variant", "a", "--out", tmp_path / "r.mcap")
    assert code == 2 and "r.csv: line 3 has 2 field(s), the header has 3" in err
    assert not (tmp_path / "r.mcap").exists()


@pytest.mark.parametrize(
    ("variables", "message"),
    [
        ({"qg": np.zeros(N - 1)}, r"log\.mat: columns differ in length \(samples: vir 200, qm "
         r"200, qg 199\)"),
        ({"qg": "text"}, r"log\.mat: variable 'qg' is not numeric"),
        ({"qg": np.ones((N, 2))}, r"log\.mat: variable 'qg' is a 200x2 matrix, not a vector"),
        ({"variant": 3.0}, r"log\.mat: scalar variable\(s\) variant would overwrite rig metadata"),
    ],
)  # fmt: skip
def test_mat_errors(tmp_path, signals, capsys, variables, message):
    source = tmp_path / "log.mat"
    scipy.io.savemat(source, {"vir": signals["u"], "qm": signals["ref"], "qg": signals["ref"],
                              **variables})  # fmt: skip
    args = ["--map", "vir=input:V", "--map", "qm=output:m"]
    if "variant" not in variables:
        args += ["--map", "qg=signal:m"]
    code, err = run(capsys, source, *args, "--sample-period", "1e-3", "--variant", "e",
                    "--out", tmp_path / "o.mcap")  # fmt: skip
    assert code == 2 and re.search(message, err), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.mat"]


def test_mat_v73_asks_for_v7(tmp_path, capsys):
    source = tmp_path / "new.mat"
    source.write_bytes(b"MATLAB 7.3 MAT-file, Platform: GLNXA64".ljust(512, b" "))
    maps = ["--map", "a=input:V", "--map", "b=output:m", "--sample-period", "1e-3"]
    code, err = run(capsys, source, *maps, "--variant", "e", "--out", tmp_path / "o.mcap")
    assert code == 2 and "new.mat: MATLAB v7.3 (HDF5) file" in err and "'-v7'" in err
    assert not (tmp_path / "o.mcap").exists()


def test_existing_output_is_kept(tmp_path, signals, capsys):
    source = write_csv(tmp_path / "log.csv", {k: list(v) for k, v in signals.items()})
    out = tmp_path / "run.mcap"
    out.write_bytes(b"keep")
    code, err = run(capsys, source, *CSV_ARGS, "--out", out)
    assert code == 2 and "run.mcap: exists already; pass --force" in err
    assert out.read_bytes() == b"keep"
    assert run(capsys, source, *CSV_ARGS, "--out", out, "--force")[0] == 0
    assert read_recording(out).n_samples == N


# -- log format 1.1: the reader's checks of SignalSample recordings ----------------------------

CHANNELS = Channels(("f",), ("N",), ("q", "p"), ("m", "rad"), ("r",), ("m",), validity=("p",))
RIG = {"variant": "ball-screw_2", "backend": "import", "sample_period_s": 0.001,
       **CHANNELS.metadata()}  # fmt: skip
EXPERIMENT = {"format_version": "1.1", "protocol": "external", "start_time": "",
              "operator": "test", "software_version": "test"}  # fmt: skip


def sample(k: int, **changes) -> dict:
    message = {"sequence": k, "device_time_us": 1000 * k, "f": 1.5, "q": 1e-3 * k, "p": 0.1,
               "p_valid": True, "r": None}  # fmt: skip
    return {**message, **changes}


def craft(path: Path, messages: list[dict], rig: dict | None = None) -> Path:
    writer = LogWriter(path, rig or RIG, EXPERIMENT, start_time_ns=0,
                       sample_schema=CHANNELS.schema())  # fmt: skip
    for message in messages:
        writer.sample(message["device_time_us"], message)
    writer.finish()
    return path


def test_signal_sample_recording(tmp_path):
    rec = read_recording(craft(tmp_path / "s.mcap", [sample(0), sample(1, p=None, p_valid=False)]))
    assert rec.variant == "ball-screw_2"
    assert (rec.input_units, rec.output_units, rec.signal_units) == (("N",), ("m", "rad"), ("m",))
    assert rec.valid.tolist() == [[True, True], [True, False]]
    assert np.isnan(rec.signals).all() and rec.declared_noise_std("q") is None


@pytest.mark.parametrize(
    ("messages", "rig", "message"),
    [
        ([sample(0, f=None)], None, "sample 0: f must be a number, got None"),
        ([sample(0, p=None)], None, "p is None although p_valid is true"),
        ([sample(0), sample(1, extra=2)], None, None),
        ([sample(0)], {"variant": "a b"}, "rig.variant 'a b' is not a model variant name"),
        ([sample(0)], {"noise_std_q": -1.0}, r"rig.noise_std_q must be a number > 0"),
        ([sample(0)], {"noise_std_q": "guess"}, "or 'estimate', got 'guess'"),
        ([sample(0)], {"noise_std_z": 1.0}, r"rig.noise_std_z names no output \(outputs: q, p\)"),
        ([sample(0)], {"output_units": "m,furlong"}, "output p: unit 'furlong' is not an SI"),
        ([sample(0)], {"inputs": "f,g"}, r"2 input\(s\) \(f,g\) but 1 input_units"),
    ],
)  # fmt: skip
def test_signal_sample_errors(tmp_path, messages, rig, message):
    path = craft(tmp_path / "e.mcap", messages, {**RIG, **(rig or {})})
    if message is None:  # an extra field only in a later sample is not checked: fine
        assert read_recording(path).n_samples == 2
        return
    with pytest.raises(LogFormatError, match=message):
        read_recording(path)


def test_rig_sample_units_and_any_variant(tmp_path):
    """H-frame recordings get the rig's units; a variant outside the built-in ones is read."""
    message = {
        "sequence": 0, "device_time_us": 0, "u1_V": 1.0, "u2_V": None, "applied1_V": 1.0,
        "applied2_V": None, "encoder1_counts": 0, "encoder2_counts": None, "phi1_rad": 0.0,
        "phi2_rad": None, "laser_x_m": 0.001, "laser_x_valid": True, "laser_y_m": None,
        "laser_y_valid": None, "limit_x_min": False, "limit_x_max": False, "limit_y_min": None,
        "limit_y_max": None, "command_sequence": None, "watchdog": False,
    }  # fmt: skip
    rig = {
        "variant": "my-hbot", "backend": "serial", "sample_period_s": 0.001, "inputs": "u1",
        "outputs": "phi1,x", "encoder_counts_per_rev": 4096, "dac_bits": 12, "dac_min_v": -10.0,
        "dac_max_v": 10.0, "laser_min_m": -0.05, "laser_max_m": 0.05,
    }  # fmt: skip
    experiment = {**EXPERIMENT, "format_version": fmt.FORMAT_VERSION}
    writer = LogWriter(tmp_path / "h.mcap", rig, experiment, start_time_ns=0)
    writer.sample(0, message)
    rec = read_recording(writer.finish())
    assert rec.variant == "my-hbot"
    assert rec.input_units == ("V",) and rec.output_units == ("rad", "m")
    assert rec.signals.shape == (1, 0) and rec.declared_noise_std("x") is None
    assert rec.units == {"u1": "V", "phi1": "rad", "x": "m"}


# -- the shipped real data ---------------------------------------------------------------------


def test_shipped_emps_recording():
    rec = read_recording(EMPS)
    assert rec.variant == "emps-axis" and rec.n_samples == 24841
    assert rec.sample_period_s == 0.001 and rec.duration_s == pytest.approx(24.84)
    assert (rec.input_names, rec.output_names, rec.signal_names) == (("vir",), ("qm",), ("qg",))
    assert (rec.input_units, rec.output_units, rec.signal_units) == (("V",), ("m",), ("m",))
    # One encoder count of qm is 50 nm: quantization noise std 50 nm / sqrt(12).
    assert rec.declared_noise_std("qm") == pytest.approx(5e-8 / math.sqrt(12), rel=1e-12)
    assert rec.rig["gtau"] == pytest.approx(35.15, abs=0.01)
    assert (rec.rig["kp"], rec.rig["kv"]) == (160.18, 243.45)
    assert "Janot" in rec.experiment["citation"]
    assert rec.experiment["source.file"] == "DATA_EMPS.mat"
    mat = scipy.io.loadmat(EMPS_MAT)
    assert rec.experiment["source.sha256"] == hashlib.sha256(EMPS_MAT.read_bytes()).hexdigest()
    np.testing.assert_array_equal(rec.inputs[:, 0], mat["vir"].ravel())
    np.testing.assert_array_equal(rec.outputs[:, 0], mat["qm"].ravel())
    np.testing.assert_array_equal(rec.signals[:, 0], mat["qg"].ravel())
    # The .mat's time has float32-like jitter (+/-2e-8 s); the log's clock counts microseconds.
    np.testing.assert_allclose(rec.time_s, mat["t"].ravel(), rtol=0, atol=5e-7)
