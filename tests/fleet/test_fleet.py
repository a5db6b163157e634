"""Fleet batch fits on Dask: manifest checks, the results store, faults, drift (hframe_id.fleet).

One small seeded fleet (2 rigs x 2 weeks, three 1 s steps a week, one rig aged: belt x 0.7) is
recorded once per module; the whole command path runs on it once (``fleet make`` -> ``batch``
on a LocalCluster of 2 worker processes -> ``fleet report``); the fault tests use a
single-thread in-process cluster.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import signal
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import yaml
from distributed import Client

from hframe_id.cli import main
from hframe_id.fitting import FitOptions
from hframe_id.fleet.drift import DEFAULT_THRESHOLD
from hframe_id.fleet.manifest import ManifestError, load_manifest
from hframe_id.fleet.runner import local_cluster, run_batch
from hframe_id.fleet.store import ResultsStore, read_results
from hframe_id.resources import models_dir
from studies.fleet import run_trials


@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("fleet") / "fleet"
    args = ["--rigs", "2", "--weeks", "2", "--seed", "3", "--out", str(out)]
    assert main(["fleet", "make", *args]) == 0
    return out


@pytest.fixture(scope="module")
def batch(fleet) -> tuple[Path, float]:
    """The batch run once on the fleet: results file and wall time [s]."""
    results = fleet / "results.parquet"
    start = time.perf_counter()
    code = main(["batch", str(fleet / "manifest.yaml"), "--results", str(results)]
                + ["--workers", "2", "--no-reports", "--quiet"])  # fmt: skip
    assert code == 0
    return results, time.perf_counter() - start


def _connect(client):
    return lambda: contextlib.nullcontext(client)


def test_fleet_make_describes_its_aging(fleet):
    aging = yaml.safe_load((fleet / "aging.yaml").read_text())
    (aged,) = aging["aged"]  # half of the rigs, the first aging kind
    assert aged["kind"] == "belt"
    assert aged["last_week_factor"] == {"k_l": 0.7, "k_r": 0.7, "k_b": 0.7}
    assert sorted([aged["rig"], *aging["not_aged"]]) == ["rig-01", "rig-02"]
    jobs = load_manifest(fleet / "manifest.yaml")
    assert [(j.rig, j.time.day) for j in jobs] == [
        ("rig-01", 5), ("rig-01", 12), ("rig-02", 5), ("rig-02", 12)
    ]  # fmt: skip
    assert all(len(j.recordings) == 3 and j.model == "hframe-8" for j in jobs)


@pytest.mark.integration
def test_batch_stores_a_row_per_fit(batch, fleet):
    results, _ = batch
    frame = read_results(results)
    assert len(frame) == 4
    assert set(frame["status"]) == {"ok"}
    assert frame["key"].is_unique
    assert {"k_l [N/m]", "k_l std [N/m]", "k_l ci95 low [N/m]", "k_l ci95 high [N/m]",
            "k_l identified", "rms x [m]", "residual_rms [noise std]", "wall_time [s]",
            "fit_id", "recordings_sha256", "run_time", "worker",
            "fitted_model"} <= set(frame.columns)  # fmt: skip
    assert set(frame["fitted_model"]) == {"hframe-8"}  # sensor weights: no larger model tried
    assert frame["residual_rms [noise std]"].between(0.8, 1.2).all()  # a matched model
    for path in frame["parameter_file"]:
        assert Path(path).is_file() and Path(path).parent == fleet / "results-fits"


@pytest.mark.integration
def test_rerun_skips_every_stored_fit(batch, fleet, capsys):
    results, first = batch
    before = results.stat().st_mtime_ns
    start = time.perf_counter()
    assert main(["batch", str(fleet / "manifest.yaml"), "--results", str(results)]) == 0
    elapsed = time.perf_counter() - start
    assert "4 already stored, 0 stored now" in capsys.readouterr().out
    assert elapsed < 2.0 < first  # no cluster is started: hashing 12 files only
    assert results.stat().st_mtime_ns == before


@pytest.mark.integration
def test_report_flags_exactly_the_aged_rigs(batch, fleet, capsys):
    results, _ = batch
    assert main(["fleet", "report", str(results), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    aging = yaml.safe_load((fleet / "aging.yaml").read_text())
    expected = {
        (a["rig"], name)
        for a in aging["aged"]
        for name, factor in a["last_week_factor"].items()
        if abs(factor - 1) > DEFAULT_THRESHOLD
    }
    assert {(f["rig"], f["parameter"]) for f in report["flagged"]} == expected
    assert report["structure_changes"] == {}
    for flag in report["flagged"]:
        # 30 % belt aging plus two weeks of 1 % scatter
        assert flag["change"] == pytest.approx(-0.3, abs=0.05)
    plots = Path(report["plots"])
    assert (plots / "k_l.png").is_file()
    assert (plots.parent / "fleet-report.md").is_file()


MONDAY = "2026-01-05T08:00:00Z"
ONE_AXIS = models_dir() / "one-axis-table2.3.yaml"


def _manifest(path: Path, fits: list[dict], defaults: dict | None = None) -> Path:
    doc = {"format_version": "1.0", "defaults": defaults or {"model": "hframe-8"}, "fits": fits}
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _week(fleet: Path, rig: str, week: int) -> list[str]:
    return sorted(str(p) for p in (fleet / rig).glob(f"week-{week:02d}-*.mcap"))


def test_a_failing_fit_is_a_row(fleet, tmp_path, client):
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(b"not an mcap file")
    manifest = _manifest(
        tmp_path / "m.yaml",
        [
            {"rig": "good", "time": MONDAY, "recordings": _week(fleet, "rig-02", 0)},
            {"rig": "bad", "time": MONDAY, "recordings": [str(broken)]},
        ],
    )
    store = ResultsStore(tmp_path / "r.parquet")
    summary = run_batch(
        load_manifest(manifest), store, _connect(client), tmp_path / "fits", reports=False
    )
    assert summary.stored == {"ok": 1, "error": 1}
    frame = read_results(tmp_path / "r.parquet").set_index("rig")
    assert frame.loc["bad", "status"] == "error"
    assert "broken.mcap" in frame.loc["bad", "message"]
    assert frame.loc["good", "status"] == "ok"


def test_interrupt_keeps_finished_rows(fleet, tmp_path, client):
    fits = [
        {"rig": rig, "time": f"2026-01-{5 + 7 * week:02d}T08:00:00Z",
         "recordings": _week(fleet, rig, week)}
        for rig in ("rig-01", "rig-02") for week in (0, 1)
    ]  # fmt: skip
    jobs = load_manifest(_manifest(tmp_path / "m.yaml", fits))
    store = ResultsStore(tmp_path / "r.parquet")

    def interrupt(row, done, total):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_batch(jobs, store, _connect(client), tmp_path / "fits", reports=False,
                  progress=interrupt)  # fmt: skip
    table = pq.read_table(tmp_path / "r.parquet")  # a whole file with the finished row
    assert table.num_rows == 1
    assert not list(tmp_path.glob(".r.parquet.*"))  # no temporary file left


@pytest.mark.slow
@pytest.mark.integration
def test_a_killed_worker_loses_no_row(fleet, tmp_path):
    """Kill one of two worker processes while it fits: its task moves to the other (or to
    the nanny's replacement) and every fit is stored."""
    jobs = load_manifest(fleet / "manifest.yaml")
    store = ResultsStore(tmp_path / "r.parquet")
    with (
        local_cluster(2) as cluster,
        Client(cluster) as client,
    ):
        # The batch's worker processes run without Dask's static glibc trim threshold (a
        # fit 1.3 -> 1.7 s under it), and with one BLAS thread each.
        environment = client.run(
            lambda: (os.environ.get("MALLOC_TRIM_THRESHOLD_"), os.environ.get("OMP_NUM_THREADS"))
        )
        assert set(environment.values()) == {(os.environ.get("MALLOC_TRIM_THRESHOLD_"), "1")}
        pids = client.run(os.getpid)
        victim = pids[sorted(pids)[0]]

        def kill_once(row, done, total):
            if done == 1:
                os.kill(victim, signal.SIGKILL)

        summary = run_batch(jobs, store, _connect(client), tmp_path / "fits", reports=False,
                            progress=kill_once)  # fmt: skip
        assert victim not in client.run(os.getpid).values()  # killed (the nanny restarts it)
    assert summary.stored == {"ok": 4}
    assert len(read_results(tmp_path / "r.parquet")) == 4


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"rig": None}, "entry 1: field 'rig': missing"),
        ({"tme": "x"}, "entry 1 (rig r1): unknown field 'tme' (did you mean 'time'?)"),
        (
            {"time": "2026-01-05T08:00:00"},
            "entry 1 (rig r1): field 'time': 2026-01-05T08:00:00 lacks a time zone",
        ),  # fmt: skip
        ({"time": "monday"}, "field 'time': 'monday' is not an ISO 8601 time"),
        ({"model": "hframe-9"}, "entry 1 (rig r1): field 'model': unknown model 'hframe-9'"),
        (
            {"recordings": ["nope.mcap"]},
            "entry 1 (rig r1): field 'recordings': nope.mcap: no such file",
        ),  # fmt: skip
        ({"free": ["k_x"]}, "field 'free': 'k_x' matches no parameter of hframe-8"),
        ({"initial": "missing.yaml"}, "field 'initial': missing.yaml: no such file"),
        ({"initial": str(ONE_AXIS)}, f"field 'initial': {ONE_AXIS}: model is 'one-axis'"),
    ],
)
def test_bad_manifest_entries_stop_before_any_work(tmp_path, capsys, change, message):
    (tmp_path / "a.mcap").write_bytes(b"")
    entry = {"rig": "r1", "time": "2026-01-05T08:00:00Z", "recordings": ["a.mcap"], **change}
    entry = {k: v for k, v in entry.items() if v is not None}
    manifest = _manifest(tmp_path / "m.yaml", [entry])
    results = tmp_path / "r.parquet"
    assert main(["batch", str(manifest), "--results", str(results)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"hframe-id: error: {manifest}: ")
    assert message in err
    assert len(err.splitlines()) == 1
    assert not results.exists()


def test_csv_manifest(tmp_path):
    for name in ("a.mcap", "b.mcap"):
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "m.csv").write_text(
        "rig,time,recordings,model,free\n"
        'r1,2026-01-05T08:00:00+00:00,a.mcap;b.mcap,hframe-8,"k_*,g_2"\n'
        "r2,2026-01-05T08:10:00+00:00,a.mcap,one-axis,\n"
    )
    first, second = load_manifest(tmp_path / "m.csv")
    assert first.recordings == (tmp_path / "a.mcap", tmp_path / "b.mcap")
    assert first.free == ("k_*", "g_2")
    assert second.model == "one-axis" and second.free is None
    assert second.initial.name == "one-axis-table2.3.yaml"


def test_repeated_run_of_a_rig_is_an_error(tmp_path):
    (tmp_path / "a.mcap").write_bytes(b"")
    entry = {"rig": "r1", "time": "2026-01-05T08:00:00Z", "recordings": ["a.mcap"]}
    with pytest.raises(ManifestError, match="entry 2 .* repeats entry 1"):
        load_manifest(_manifest(tmp_path / "m.yaml", [entry, entry]))


def test_study_trials_run_on_the_cluster(client):
    seen = []
    (trial,) = run_trials(_connect(client), "hframe-8", [1], on_trial=seen.append)
    assert seen == [trial] and trial.seed == 1
    assert trial.success and trial.max_error < 0.01  # the recovery tests' 1 %


def test_a_solver_failure_is_a_failed_row_without_parameter_file(fleet, tmp_path, monkeypatch):
    from hframe_id.fleet import job as job_module

    def one_iteration(job):
        # One iteration a stage, sensor weights: with estimated noise levels the noise rounds
        # would go on from there (ten more stages of one iteration converge on this fleet).
        options = FitOptions(threads=1, verbose=0, noise="sensor")
        return dataclasses.replace(options, max_iterations=1)

    monkeypatch.setattr(job_module, "batch_options", one_iteration)
    job = load_manifest(fleet / "manifest.yaml")[0]
    row = job_module.run_job(job, "k", ["d"], tmp_path, reports=False)
    assert row["status"] == "failed" and row["message"]
    assert row["parameter_file"] is None and row["fit_id"]
    assert "k_l [N/m]" in row  # the estimates where the solver stopped
