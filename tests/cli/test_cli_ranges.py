"""Range checks of numeric options and metadata (issue 27, item 3): a value out of range, or
inconsistent with the data it is used on, is one ``hframe-id: error:`` line naming the option
(or file, or field) and the value, exit status 2, before any work, nothing written."""

from __future__ import annotations

from pathlib import Path

import pytest
from refusals import refused
from test_cli_hostile_files import _recording

from hframe_id.cli import main

ROOT = Path(__file__).resolve().parents[2]
H8 = ROOT / "models" / "hframe-8-table4.2.yaml"
REC = ROOT / "datasets" / "4V_xmotion.mcap"
RECORD = ["record", "--rig", "sim", "--params", H8, "--fast", "--out", "run.mcap"]


@pytest.fixture
def work(tmp_path, monkeypatch) -> Path:
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.parametrize(
    ("extra", "option", "value"),
    [
        (["--seed", "-1", "--v1", "1", "--v2", "1"], "--seed", "-1"),
        (["--protocol", "pulse", "--amplitude", "1", "--width", "0"], "--width", "0"),
        (["--protocol", "multisine", "--rms", "-1"], "--rms", "-1"),
        (["--protocol", "multisine", "--rms", "nan"], "--rms", "nan"),
        (["--protocol", "multisine", "--rms", "1e308"], "multisine rms", "overflows"),
        (["--protocol", "multisine", "--band", "0.5", "5000"], "--band", "Nyquist frequency 500"),
        (["--protocol", "multisine", "--duration", "0.1"], "--duration", "one --period 2 s"),
        (
            ["--rig", "serial", "--port", "/dev/null", "--watchdog-ms", "99999"],
            "--watchdog-ms",
            "<= 60000",
        ),
    ],
)
def test_record_option_out_of_range(work, capsys, extra, option, value):
    refused([*RECORD, *extra], capsys, option, value)
    assert list(work.iterdir()) == []


def test_simulate_seed_and_sample_time(work, capsys):
    step = ["simulate", "--params", H8, "--step", "1,4", "--duration", "0.05", "--out", "s.csv"]
    refused([*step, "--mcap", "s.mcap", "--seed", "-1"], capsys, "--seed", "-1")
    refused([*step, "--sample-time", "inf"], capsys, "--sample-time", "inf")
    assert list(work.iterdir()) == []


def _counts_csv(folder: Path) -> Path:
    path = folder / "counts.csv"
    path.write_text("time [s],u1 [V],pos [counts]\n0,1,10\n0.001,1,20\n0.002,1,30\n")
    return path


def test_simulate_seed_without_mcap(work, capsys):
    """The sensor noise seed of --mcap's recording, ignored without a word when none is made."""
    argv = ["simulate", "--params", H8, "--step", "1,1", "--duration", "0.1", "--out", "s.csv"]
    refused([*argv, "--seed", "5"], capsys, "--seed is for --mcap")
    assert list(work.iterdir()) == []


def test_import_infinite_counts_per_rev(work, capsys):
    csv = _counts_csv(work)
    maps = ["--map", "time [s]=time:s", "--map", "u1 [V]=input:V:u1"]
    maps += ["--map", "pos [counts]=output:counts:pos"]
    argv = ["import", csv, *maps, "--counts-per-rev", "inf", "--variant", "x", "--out", "c.mcap"]
    refused(argv, capsys, "--counts-per-rev", "inf")
    assert sorted(p.name for p in work.iterdir()) == ["counts.csv"]


def test_import_sample_period_against_the_time_column(work, capsys):
    csv = _counts_csv(work)
    maps = ["--map", "time [s]=time:s", "--map", "u1 [V]=input:V:u1"]
    maps += ["--map", "pos [counts]=output:counts:pos", "--counts-per-rev", "1000"]
    argv = ["import", csv, *maps, "--sample-period", "0.01", "--variant", "x", "--out", "c.mcap"]
    refused(argv, capsys, "--sample-period", "0.01", "1 ms apart")
    assert sorted(p.name for p in work.iterdir()) == ["counts.csv"]


def test_recording_sample_period_against_the_device_clock(work, capsys):
    def slower(i: int, message: dict) -> dict:  # device clock at 10 ms, 1 ms declared
        return {**message, "device_time_us": message["device_time_us"] * 10}

    rec = _recording(work / "clock.mcap", slower)
    argv = ["simulate", "--params", H8, "--recording", rec, "--out", "s.csv"]
    refused(argv, capsys, "clock.mcap", "rig.sample_period_s 0.001", "10 ms apart")
    assert sorted(p.name for p in work.iterdir()) == ["clock.mcap"]


@pytest.mark.parametrize(
    ("options", "named"),
    [
        (["--max-lag", "100000"], "--max-lag 100000"),
        (["--horizon", "100000"], "--window + --horizon 100010"),
        (["--window", "995"], "--window + --horizon 1005"),
        (["--init-samples", "5000"], "--init-samples 5000"),
    ],
)
def test_validate_spans_longer_than_the_recording(work, capsys, options, named):
    """Every option counted in samples is checked against the recording's length (the
    horizon, window and RMSE start were accepted, and gave empty or NaN scores)."""
    argv = ["validate", H8, REC, *options, "--plot", "plots"]
    refused(argv, capsys, named, "1000 samples")
    assert list(work.iterdir()) == []


def test_fit_shooting_interval_longer_than_the_record(work, capsys):
    argv = ["fit", REC, "--shooting-interval", "100000", "--quiet", "--out-dir", "fits"]
    refused(argv, capsys, "4V_xmotion", "100000", "1000 samples")
    assert list(work.iterdir()) == []


def test_fit_channel_with_no_valid_sample(work, capsys):
    def blind(i: int, message: dict) -> dict:  # the x laser never in range
        return {**message, "laser_x_m": None, "laser_x_valid": False}

    rec = _recording(work / "blind.mcap", blind)
    argv = ["fit", rec, "--quiet", "--out-dir", "fits"]
    refused(argv, capsys, "blind", "no valid sample of output x")
    assert sorted(p.name for p in work.iterdir()) == ["blind.mcap"]


@pytest.mark.parametrize(
    ("line", "value"),
    [("J_M1 [kg m^2]: 0.000112", "1.0e-300"), ("r [m]: 0.0194", "1.0e+300")],
    ids=["inertia-1e-300", "radius-1e300"],
)
@pytest.mark.parametrize(
    "command", ["simulate", "record", "control", "validate", "fit", "fit-known", "design"]
)
def test_a_model_too_stiff_to_simulate(work, capsys, command, line, value):
    """An inertia of 1e-300 kg m^2 asked for ~1e300 RK4 substeps: the simulation built its
    expression for ever (gigabytes, deaf to SIGTERM); a radius of 1e300 m was a LinAlgError
    traceback (in a fit's start screen and a design's simulation too; a design with the
    inertia was refused for "no valid sample"). Refused before any work, naming the value."""
    name = line.partition(":")[0]
    path = work / "extreme.yaml"
    path.write_text(H8.read_text().replace(line, f"{name}: {value}"))
    argv = {
        "simulate": ["simulate", "--params", path, "--step", "1,1", "--duration", "0.1",
                     "--out", "s.csv"],
        "record": ["record", "--rig", "sim", "--params", path, "--v1", "1", "--v2", "1",
                   "--fast", "--out", "r.mcap"],
        "control": ["control", "--params", path, "--kp", "5", "--csv", "c.csv"],
        "validate": ["validate", path, REC, "--plot", "plots"],
        "fit": ["fit", REC, "--initial", path, "--out-dir", "fits"],
        "fit-known": ["fit", REC, "--known", path, "--out-dir", "fits"],
        "design": ["design", "--params", path, "--duration", "1", "--max-voltage", "6",
                   "--travel", "x=-0.2:0.2", "--travel", "y=-0.2:0.2", "--out", "d.csv"],
    }[command]  # fmt: skip
    refused([*argv, "--quiet"], capsys, "too stiff to simulate", f"{name.split()[0]} = ")
    assert sorted(p.name for p in work.iterdir()) == ["extreme.yaml"]


@pytest.mark.parametrize("line", ["r [m]: 0.0194", "K_t [N m/A]: 0.023"])
def test_linearize_extreme_parameter_values(work, capsys, line):
    name = line.partition(":")[0]
    path = work / "extreme.yaml"
    path.write_text(H8.read_text().replace(line, f"{name}: 1.0e+300"))
    refused(["linearize", path], capsys, "extreme.yaml", "1e+300", name.split()[0])


#: The numeric options of fit, control, fleet and batch, declared with their range
#: (``add_number``): (command line without the option, option, a value out of range).
FIT = ["fit", REC, "--out-dir", "fits"]
CONTROL = ["control", "--params", H8, "--csv", "c.csv"]
FLEET_MAKE = ["fleet", "make", "--out", "fleet"]
OUT_OF_RANGE = [
    (FIT, "--shooting-interval", "0"),
    (FIT, "--starts", "0"),
    (FIT, "--starts", "100000"),  # ran for hours
    (FIT, "--max-iterations", "1000000000"),
    (FIT, "--start-seed", "-1"),
    (FIT, "--max-iterations", "0"),
    (FIT, "--bound-factor", "1"),
    (FIT, "--step-tol=-1e-6", "-1e-6"),
    (FIT, "--defect-tol", "nan"),
    (FIT, "--identifiability-threshold", "0"),
    (FIT, "--max-misfit", "inf"),
    (FIT, "--threads", "0"),
    ([*CONTROL, "--kp", "1"], "--ki", "-1"),
    ([*CONTROL, "--kp", "1"], "--kd", "inf"),
    (CONTROL, "--kp", "-150"),
    ([*CONTROL, "--kp", "1"], "--motor2-gain-scale", "0"),
    ([*CONTROL, "--kp", "1"], "--sample-time", "0"),
    ([*CONTROL, "--kp", "1"], "--delay-samples", "-1"),
    ([*CONTROL, "--kp", "1"], "--side", "0"),
    ([*CONTROL, "--kp", "1"], "--v-max", "-0.1"),
    ([*CONTROL, "--kp", "1"], "--f-a", "0.6"),
    ([*CONTROL, "--kp", "1", "--trajectory", "points", "--points", "0,0;0.01,0"], "--dwell", "-1"),
    ([*CONTROL, "--kp", "1"], "--settle", "nan"),
    ([*CONTROL, "--kp", "1"], "--substeps", "0"),
    ([*FLEET_MAKE, "--weeks", "2"], "--rigs", "0"),
    ([*FLEET_MAKE, "--rigs", "1"], "--weeks", "1"),
    ([*FLEET_MAKE, "--rigs", "100000"], "--weeks", "100000"),
    (["batch", "m.yaml", "--results", "r.parquet"], "--workers", "100000"),
    (
        ["design", "--params", H8, "--duration", "1", "--max-voltage", "2", "--out", "d.csv"],
        "--draws",
        "100000",
    ),
    ([*FLEET_MAKE, "--rigs", "1", "--weeks", "2"], "--seed", "-1"),
    (["fleet", "report", "r.parquet"], "--threshold", "1"),
    (["batch", "m.yaml", "--results", "r.parquet"], "--workers", "0"),
]


@pytest.mark.parametrize(("argv", "option", "value"), OUT_OF_RANGE)
def test_numeric_option_out_of_range_of_fit_control_fleet_batch(work, capsys, argv, option, value):
    given = [option] if "=" in option else [option, value]  # "--opt=-1": argparse's way
    refused([*argv, *given], capsys, option.split("=")[0], value)
    assert list(work.iterdir()) == []


def test_control_workspace_must_be_finite(work, capsys):
    argv = [*CONTROL, "--kp", "1", "--workspace", "-0.1", "inf", "-0.1", "0.1"]
    refused(argv, capsys, "--workspace", "inf")


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "--params", H8, "--step", "1,4", "--duration", "0.05", "--out", "s.csv"],
        ["control", "--params", H8, "--kp", "150", "--csv", "c.csv"],
    ],
    ids=["simulate", "control"],
)
def test_substeps_bounded_above(work, capsys, argv):
    """--substeps 100000000 on 50 samples ran for minutes."""
    refused([*argv, "--substeps", "100000000"], capsys, "--substeps", "<= 10000")
    assert list(work.iterdir()) == []


def test_fit_empty_free_list(work, capsys):
    """--free '' fitted the default free set as if no --free were given."""
    refused(["fit", REC, "--out-dir", "fits", "--free", ""], capsys, "free")
    assert list(work.iterdir()) == []


@pytest.mark.parametrize("option", ["--free", "--focus"])
def test_design_empty_name_list(work, capsys, option):
    """design --free '' designed for the default free set, as if no --free were given."""
    argv = ["design", "--params", H8, "--duration", "1", "--max-voltage", "2", "--out", "d.csv"]
    refused([*argv, "--travel", "x=-0.2:0.2", "--travel", "y=-0.2:0.2", option, " , "], capsys,
            option, "names no parameter")  # fmt: skip
    assert list(work.iterdir()) == []


@pytest.mark.parametrize(
    ("rig", "named"),
    [
        ({"dac_bits": "100000"}, "rig.dac_bits must be a number >= 1 and <= 32, got 100000"),
        ({"limit_x_min_m": "1", "limit_x_max_m": "-1"}, "rig.limit_x_min_m 1 must be a number"),
    ],
    ids=["dac-bits", "limits"],
)
def test_rig_metadata_out_of_range_names_the_file(work, capsys, rig, named):
    """A DAC of 100000 bits was refused by fit and validate without naming the file (and
    accepted by inspect and simulate); inverted limit switches were accepted everywhere."""
    rec = _recording(work / "rig.mcap", lambda i, m: m, rig=rig)
    for argv in (["inspect", rec], ["fit", rec, "--quiet", "--out-dir", "fits"]):
        refused(argv, capsys, "rig.mcap", named)
    assert sorted(p.name for p in work.iterdir()) == ["rig.mcap"]


def test_fit_unknown_recorded_variant_names_the_file(work, capsys):
    """A recording naming a variant that does not exist: 'unknown model variant' without
    saying which file named it."""
    rec = _recording(work / "odd.mcap", lambda i, m: m, rig={"variant": "hframe-99"})
    refused(["fit", rec, "--out-dir", "fits"], capsys, "odd.mcap", "rig.variant", "'hframe-99'")
    assert sorted(p.name for p in work.iterdir()) == ["odd.mcap"]


def test_import_time_beyond_the_device_clock(work, capsys):
    """A time of 1e300 s overflowed the cast to microseconds (numpy's warning line), then
    was reported as time not increasing."""
    (work / "t.csv").write_text("t,u,x\n0,1,0\n1e300,1,0\n")
    argv = ["import", "t.csv", "--map", "t=time:s", "--map", "u=input:V", "--map", "x=output:m"]
    refused([*argv, "--variant", "a", "--out", "i.mcap"], capsys, "t.csv", "1e+300 s",
            "beyond the log's clock")  # fmt: skip
    assert sorted(p.name for p in work.iterdir()) == ["t.csv"]


def test_validate_channel_with_no_valid_sample_warns_nothing(work, capsys):
    """validate on a recording whose x laser is never valid printed numpy's 'Mean of empty
    slice' and two division warnings; the channel is shown without scores, and no warning."""

    def blind(i: int, message: dict) -> dict:
        return {**message, "laser_x_m": None, "laser_x_valid": False}

    rec = _recording(work / "blind.mcap", blind)
    assert main(["validate", str(H8), str(rec), "--quiet", "--horizon", "0"]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    assert "x  " in captured.out


def test_fit_refuses_a_recording_given_twice(work, capsys):
    """fit R R (here once through a link) fitted one recording twice: its weight doubled,
    and its cross-validation held it out against itself."""
    (work / "same.mcap").symlink_to(REC)
    argv = ["fit", REC, "same.mcap", "--quiet", "--out-dir", "fits"]
    refused(argv, capsys, "recording same.mcap", "given twice", REC.name)
    assert sorted(p.name for p in work.iterdir()) == ["same.mcap"]


@pytest.mark.parametrize(
    ("extra", "named"),
    [
        (["--protocol", "multisine", "--v1", "5"], "--v1 is for --protocol step, not multisine"),
        (["--v1", "1", "--v2", "1", "--rms", "5"], "--rms is for --protocol multisine, not step"),
        (["--v1", "1", "--v2", "1", "--band", "1", "5"], "--band is for --protocol multisine"),
        (["--protocol", "pulse", "--amplitude", "1", "--step", "0.2"], "--step is for --protocol"),
        (["--protocol", "csv", "--csv", "v.csv", "--pre-roll", "1"], "--pre-roll is for"),
    ],
    ids=["multisine-v1", "step-rms", "step-band", "pulse-step", "csv-pre-roll"],
)
def test_record_refuses_another_protocols_option(work, capsys, extra, named):
    """An option of another protocol was silently ignored: ``--protocol multisine --v1 5``
    recorded a multisine of the default 3 V rms."""
    (work / "v.csv").write_text("time [s],u1 [V],u2 [V]\n0,1,1\n")
    refused([*RECORD, *extra], capsys, named)
    assert sorted(p.name for p in work.iterdir()) == ["v.csv"]
