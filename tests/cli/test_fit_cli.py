"""`hframe-id fit` end to end: files on success, none on failure, errors before solving."""

import contextlib
import io
import math
from pathlib import Path

import pytest
import yaml

from hframe_id.cli import main
from hframe_id.fitting.jackknife import student_t_quantile
from hframe_id.parameters import load_parameter_file

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "datasets" / "4V_xmotion.mcap"


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    out = tmp_path_factory.mktemp("fits")
    status = main(["fit", str(DATA), "--out-dir", str(out), "--quiet"])
    return status, out


def test_successful_fit_writes_a_loadable_versioned_parameter_file(fitted):
    status, out = fitted
    assert status == 0
    (yaml_path,) = out.glob("*.yaml")
    params = load_parameter_file(yaml_path, variant="hframe-8")
    prov = params.provenance
    assert prov["fit_id"] == yaml_path.stem
    assert prov["datasets"][0]["sha256"] and len(prov["datasets"][0]["sha256"]) == 64
    # recorded relative to the project (the same on every clone), not to the working directory
    assert prov["datasets"][0]["file"] == "datasets/4V_xmotion.mcap"
    assert prov["solver"]["success"] is True
    # sim-rig data fitted with the model that made them: residuals at the noise model's level
    # (1 = exactly the noise; the smoothed-Coulomb and integrator differences add a little)
    assert 0.8 < prov["solver"]["residual_rms_noise_std"] < 1.5
    assert set(prov["free_parameters"]) >= {"k_l", "k_r", "k_b", "g_2"}
    # every free parameter has estimate, error, interval and identifiability
    for key, entry in params.uncertainty["parameters"].items():
        low, high = entry["interval_95"]
        assert low <= entry["estimate"] <= high, key
        assert isinstance(entry["identified"], bool)
    # the rig's aged belt (k x 0.85 of Table 4.1) must show in the fit, far beyond the interval
    truth = load_parameter_file(ROOT / "datasets" / "truth" / "hframe-8-rig.yaml")
    assert params.values["k_l"] == pytest.approx(truth.values["k_l"], rel=0.01)


def test_report_compares_with_table_4_2_and_truth(fitted):
    _, out = fitted
    (report,) = out.glob("*-report.md")
    text = report.read_text()
    assert "Table 4.1 + 4.2" in text and "error vs truth" in text
    plots = list(out.glob("*-plots/*.png"))
    assert any(p.name == "4V_xmotion.png" for p in plots)


def test_failed_fit_writes_no_parameter_file(tmp_path, capsys):
    # The fit converges at the noise level (residual rms ~1 sensor std); asked for 0.5 it
    # fails as a fit converged far from the data does.
    status = main(
        ["fit", str(DATA), "--out-dir", str(tmp_path), "--quiet", "--noise", "sensor",
         "--max-misfit", "0.5"]
    )  # fmt: skip
    assert status == 1
    assert not list(tmp_path.glob("*.yaml"))
    (report,) = tmp_path.glob("*-report.md")
    text = report.read_text()
    assert "FAILED" in text and "not assessed (fit failed)" in text
    out, err = capsys.readouterr()
    assert "no parameter file written" in err
    # a failed fit's error estimates mean nothing: no parameter is called identified
    assert "not assessed (fit failed)" in out and " identified" not in out


def test_same_second_fits_never_share_files(tmp_path):
    from hframe_id.fitting.output import unused_fit_id

    assert unused_fit_id(tmp_path, "hframe-8-x") == "hframe-8-x"
    (tmp_path / "hframe-8-x-report.md").write_text("a failed fit's report")
    assert unused_fit_id(tmp_path, "hframe-8-x") == "hframe-8-x-2"
    (tmp_path / "hframe-8-x-2-plots").mkdir()
    assert unused_fit_id(tmp_path, "hframe-8-x") == "hframe-8-x-3"


def test_bare_names_are_found_from_any_directory(tmp_path, monkeypatch):
    from hframe_id.cli.fit_command import resolve_dataset

    monkeypatch.chdir(tmp_path)
    assert resolve_dataset("4V_xmotion.mcap").resolve() == DATA.resolve()


def test_an_unusable_out_dir_fails_before_solving(tmp_path, capsys):
    target = tmp_path / "a_file"
    target.write_text("not a directory")
    status = main(["fit", str(DATA), "--out-dir", str(target / "sub"), "--quiet"])
    assert status == 2
    err = capsys.readouterr().err
    assert err.startswith("hframe-id: error: --out-dir") and "is not a directory" in err
    status = main(["fit", str(DATA), "--out-dir", str(target), "--quiet"])
    assert status == 2
    assert "exists and is not a directory" in capsys.readouterr().err


def test_a_fit_far_above_the_noise_level_fails(tmp_path, capsys):
    # The same converged fit as above (residual rms ~1 noise std) against a limit below it:
    # what a local optimum far from the data looks like to the user.
    status = main(["fit", str(DATA), "--out-dir", str(tmp_path), "--quiet", "--max-misfit", "0.5"])
    assert status == 1
    assert not list(tmp_path.glob("*.yaml"))
    assert "converged to a poor fit: residual rms" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["no_such.mcap"], "no such recording"),
        ([str(DATA), "--free", "k_q"], "k_q"),
        ([str(DATA), "--bounds", "k_l=1:2"], "k_l"),
        ([str(DATA), "--bounds", "k_l=abc"], "LOW:HIGH"),
        ([str(DATA), "--shooting-interval", "0"], "--shooting-interval must be >= 1, got '0'"),
        ([str(DATA), "--max-misfit", "0"], "--max-misfit must be > 0, got '0'"),
        ([str(DATA), "--initial", str(ROOT / "models" / "one-axis-table2.3.yaml")], "one-axis"),
        ([str(DATA), str(ROOT / "datasets" / "5V_oneaxis.mcap")], "one-axis"),
        ([str(DATA), "--gauss-newton", "radius=2"], "--gauss-newton: no setting 'radius'"),
        ([str(DATA), "--gauss-newton", "max_radius"], "must look like NAME=VALUE"),
        ([str(DATA), "--strategy", "restart_limit=2.5"], "restart_limit: '2.5' is not a whole"),
        ([str(DATA), "--strategy", "restart_factors=1.2,x"], "restart_factors: 'x' is not a"),
        ([str(DATA), "--gauss-newton", "merit_rho=1"], "gauss_newton.merit_rho must be < 1"),
    ],
)
def test_bad_input_fails_before_solving_and_writes_nothing(tmp_path, capsys, args, message):
    status = main(["fit", *args, "--out-dir", str(tmp_path / "out"), "--quiet"])
    assert status == 2
    err = capsys.readouterr().err
    assert err.startswith("hframe-id: error:") and message in err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_fit_file_header_is_plain_yaml(fitted):
    _, out = fitted
    (yaml_path,) = out.glob("*.yaml")
    doc = yaml.safe_load(yaml_path.read_text())
    assert list(doc)[:4] == ["format_version", "model", "title", "source"]
    assert all(" [" in key for key in doc["parameters"])


def _record(folder: Path, params: Path, volts: tuple[float, float], name: str) -> Path:
    """A 0.4 s step recorded on the sim rig from ``params`` (unpaced, ~1 s)."""
    path = folder / name
    v1, v2 = (str(v) for v in volts)
    status = main(["record", "--rig", "sim", "--params", str(params), "--fast", "--v1", v1,
                   "--v2", v2, "--step", "0.3", "--duration", "0.4", "--out", str(path),
                   "--quiet"])  # fmt: skip
    assert status == 0
    return path


@pytest.fixture(scope="module")
def mismatched_fit(tmp_path_factory):
    """An x-motion step of the 20th-order plant (Table 3.1) fitted with hframe-8: the model
    cannot follow the encoders at their quantization noise (~10 s)."""
    folder = tmp_path_factory.mktemp("h20")
    data = _record(folder, ROOT / "models" / "hframe-20-table3.1.yaml", (-4, 4), "h20_x.mcap")
    out = folder / "fits"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        status = main(["fit", str(data), "--model", "hframe-8", "--free", "k_l,k_r",
                       "--out-dir", str(out), "--quiet"])  # fmt: skip
    return status, out, printed.getvalue()


def test_hframe20_plant_fitted_with_hframe8_succeeds_with_a_mismatch_statement(mismatched_fit):
    status, out, printed = mismatched_fit
    assert status == 0
    assert "model mismatch: The model does not follow the data" in printed
    assert "estimated noise std" in printed and " mm " in printed
    (report,) = out.glob("*-report.md")
    text = report.read_text()
    # the plant's truth compared through its section-4.1 reduction, not a KeyError
    assert "truth (section-4.1 reduction of the plant)" in text
    assert "does not follow the data at the sensors' noise level" in text
    (yaml_path,) = out.glob("*.yaml")
    noise = load_parameter_file(yaml_path, variant="hframe-8").provenance["noise"]
    assert noise["model_mismatch"] is True
    assert noise["channels"]["phi1"]["residual_rms [sensor std]"] > 10


def test_initial_of_another_variant_fails_before_reading_recordings(tmp_path, capsys):
    h20 = str(ROOT / "models" / "hframe-20-table3.1.yaml")
    status = main(["fit", "no_such.mcap", "--model", "hframe-8", "--initial", h20,
                   "--out-dir", str(tmp_path / "out")])  # fmt: skip
    assert status == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("hframe-id: error:")
    assert "'hframe-20'" in err and "'hframe-8'" in err and "no such recording" not in err
    assert not (tmp_path / "out").exists()


def test_several_recordings_get_a_leave_one_out_table(tmp_path, capsys):
    table = ROOT / "models" / "hframe-8-table4.2.yaml"
    files = [
        str(_record(tmp_path, table, volts, name))
        for name, volts in (("x.mcap", (-4, 4)), ("y.mcap", (-4, -4)))
    ]
    capsys.readouterr()
    args = ["fit", *files, "--free", "k_l,k_r", "--noise", "sensor"]
    assert main([*args, "--out-dir", str(tmp_path / "cv")]) == 0
    err = capsys.readouterr().err
    assert "cross-validation 1/2: fitting without x.mcap" in err
    assert "cross-validation 2/2: fitting without y.mcap" in err
    (report,) = (tmp_path / "cv").glob("*-report.md")
    assert "## Leave-one-recording-out cross-validation" in report.read_text()
    assert "95 % interval, experiments (jackknife)" in report.read_text()
    # The parameter file carries the jackknife interval beside the fit's own: 2 folds, so
    # Student's t with 1 degree of freedom, in log(p) around the estimate.
    (fitted,) = (tmp_path / "cv").glob("*.yaml")
    k_l = yaml.safe_load(fitted.read_text())["uncertainty"]["parameters"]["k_l [N/m]"]
    low, high = k_l["interval_95_jackknife"]
    factor = math.exp(student_t_quantile(0.975, 1) * k_l["jackknife_std"] / k_l["estimate"])
    assert (low, high) == pytest.approx((k_l["estimate"] / factor, k_l["estimate"] * factor))
    assert main([*args, "--out-dir", str(tmp_path / "no-cv"), "--no-cross-validation"]) == 0
    assert "cross-validation" not in capsys.readouterr().err
    (report,) = (tmp_path / "no-cv").glob("*-report.md")
    assert "Leave-one-recording-out" not in report.read_text()


def test_json_says_how_each_record_started_and_what_the_fit_beat(tmp_path, capsys):
    """The shipped step starts at rest; the fit's simulation criterion is the lowest of the
    points it knows (the start, the equation-error estimate, Table 4.1)."""
    import json

    status = main(["fit", str(DATA), "--out-dir", str(tmp_path), "--no-plots", "--json"])
    assert status == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["initial_states"] == {"4V_xmotion.mcap": "rest"}
    points = summary["known_points"]
    assert {"fit", "the start", "hframe-8-table4.1.yaml"} <= set(points)
    assert points["fit"] == min(points.values())
    # Replayed from the replay's rest state the fit's own optimum over its belt-free position
    # (the encoders' quantization phase) is lost: never lower than from its own states.
    assert summary["replayed_criterion"] >= points["fit"]


def test_a_multistart_portfolio_reports_how_many_starts_reached_the_best(tmp_path, capsys):
    """Matched data: from the start and two draws x/÷2 around it, every start reaches the
    same optimum, and the summary, --json and the report say so."""
    import json

    argv = ["fit", str(DATA), "--out-dir", str(tmp_path), "--no-plots", "--json", "--starts", "3"]
    assert main(argv) == 0
    out, err = capsys.readouterr()
    starts = json.loads(out)["starts"]
    assert starts["reached_best"] == 3 and len(starts["outcomes"]) == 3
    assert "multistart: 3 of 3 starts reached the best optimum" in err
    (report,) = tmp_path.glob("*-report.md")
    assert "multistart: 3 of 3 starts" in report.read_text()


def test_json_says_where_the_fit_began_and_start_as_given_keeps_the_start(tmp_path, capsys):
    """From Table 4.2, the default start (its own file judged once, as the start), the fit
    begins from the best point it knows; ``--start-as-given`` skips the screen, says so."""
    import json

    argv = ["fit", str(DATA), "--out-dir", str(tmp_path), "--no-plots", "--json"]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    began = summary["began_from"]
    criteria = began["criteria"]
    assert list(criteria) == ["the start", "the equation-error estimate", "hframe-8-table4.1.yaml"]
    # Matched data: the equation-error estimate simulates the step better than Table 4.2.
    assert began["label"] == "the equation-error estimate" and began["skipped"] is None
    assert criteria[began["label"]] == min(criteria.values())
    assert "began from the equation-error estimate" in summary["message"]
    assert main([*argv, "--start-as-given"]) == 0
    began = json.loads(capsys.readouterr().out)["began_from"]
    assert began == {"label": "the start", "criteria": {}, "skipped": "off"}


def test_tuning_settings_reach_the_fit_and_its_provenance():
    """``--gauss-newton`` and ``--strategy`` give ``FitOptions`` their settings, each value
    read as its default is (whole number, number, tuple); the parameter file's provenance
    records what they change (``FitOptions.describe``)."""
    from hframe_id.cli import build_parser
    from hframe_id.cli.fit_options import fit_options

    argv = [
        "fit",
        str(DATA),
        "--gauss-newton",
        "max_radius=2",
        "--gauss-newton",
        "watchdog_patience=7",
        "--strategy",
        "restart_factors=1.2,1.5",
    ]
    options = fit_options(build_parser("fit").parse_args(argv))
    assert options.gauss_newton.max_radius == 2.0
    assert options.gauss_newton.watchdog_patience == 7
    assert options.strategy.restart_factors == (1.2, 1.5)
    described = options.for_model("hframe-8").describe()
    assert described["gauss_newton"] == {"max_radius": 2.0, "watchdog_patience": 7}
    assert described["strategy"] == {"restart_factors": (1.2, 1.5)}
