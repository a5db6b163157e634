"""Multistart and bootstrap studies on Dask, and realistic-plant fleets (hframe_id.fleet).

The studies run on a single-thread in-process LocalCluster (the command line reaches it by
its address, ``--scheduler``), on three of the shipped 1 s hframe-8 sim recordings
(``datasets/``, generated from ``datasets/truth/hframe-8-rig.yaml`` with the rig's sensor
models): a fit there takes 1.5-4 s.
"""

from __future__ import annotations

import contextlib
import json
import math

import numpy as np
import pytest
import yaml

from hframe_id.fleet import synthetic
from hframe_id.fleet.synthetic import make_fleet
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings import read_recording
from hframe_id.resources import datasets_dir
from hframe_id.rig.plant import recording_plant
from studies.fleet import (
    main,
    run_bootstrap,
    study_setup,
    summarize_bootstrap,
)

DATASETS = datasets_dir()
RECORDINGS = [str(DATASETS / f) for f in ("2V_xmotion.mcap", "4V_xmotion.mcap", "4V_ymotion.mcap")]
TRUTH = DATASETS / "truth" / "hframe-8-rig.yaml"


def test_multistart_from_20_percent_starts_finds_the_truths_optimum(client, capsys):
    args = [*RECORDINGS, "--initial", str(TRUTH), "--starts", "3", "--spread", "0.2"]
    code = main(["multistart", *args, "--seed", "5", "--scheduler", client.scheduler.address,
                 "--json"])  # fmt: skip
    assert code == 0
    out = capsys.readouterr()
    assert out.err.count("start ") == 3  # a progress line per finished start
    summary = json.loads(out.out)
    starts = [o["start"] for o in summary["outcomes"]]
    truth = load_parameter_file(TRUTH).values
    # The starts really are spread: some parameter at least 10 % off in every start.
    assert all(max(abs(s[n] / truth[n] - 1) for n in s) > 0.1 for s in starts)
    # Model-generated data, starts within ~20 % (1 sigma): one optimum, reached from all.
    assert summary["by_status"]["ok"] == 3
    assert len(summary["reached"]) == 3
    # Sensor noise in every fit (no mismatch): compared by cost, within one unit of chi^2
    # plus 1e-6 of it (5.4e3 here: three 1 s runs, 4 channels).
    assert summary["compared_by"] == "cost"
    assert summary["best_value"] == summary["best_cost"]
    assert summary["tolerance"] == pytest.approx(0.5 + 1e-6 * summary["best_cost"])
    for o in summary["outcomes"]:
        # Concentrated likelihood ~ N (ln(rms / sensor std) + 1/2), rms ~1 sensor std.
        assert o["objective"] == pytest.approx(0.5 * 12000, rel=0.2)
    for name, p in summary["parameters"].items():
        # It is the truth's optimum: the truth within 4.5 std errors (over 16 parameters a
        # normal error exceeds that with probability ~1e-4)...
        assert abs(p["best"] - truth[name]) < 4.5 * p["std_error"], name
        # ... and the starts agree far below the noise's uncertainty (the solver stops at a
        # relative parameter step of 1e-6; std errors are 1e-4 to 1e-3 relative).
        assert p["spread_over_std_error"] < 0.05, name


@pytest.mark.slow  # 7-9 s of fits on a quiet machine
def test_parametric_bootstrap_std_is_of_the_order_of_the_std_error(client):
    setup = study_setup(RECORDINGS, TRUTH)
    seen = []
    fit, replicates, method = run_bootstrap(
        lambda: contextlib.nullcontext(client),
        setup,
        4,
        method="parametric",
        seed=2,
        on_outcome=seen.append,
    )
    assert method == "parametric"
    assert len(seen) == 5 and fit.ok  # the fit of the data first, then each replicate
    assert [r.index for r in replicates] == [0, 1, 2, 3]
    assert all(r.ok for r in replicates)
    summary = summarize_bootstrap(fit, replicates)
    ratios = []
    for name, p in summary["parameters"].items():
        assert math.isfinite(p["bootstrap_std"]) and p["bootstrap_std"] > 0, name
        low, high = p["bootstrap_ci95"]
        assert low <= high
        ratios.append(p["bootstrap_over_std_error"])
    # On the model's own data the std error is the estimates' std; with 4 replicates the
    # sample std / true std is sqrt(chi2_3 / 3): 99 % of draws in [0.15, 2.1]. Each of the 16
    # ratios within [0.1, 3], their median within [0.5, 2] (a 3x wrong std error fails it).
    assert all(0.1 < r < 3.0 for r in ratios), ratios
    assert 0.5 < float(np.median(ratios)) < 2.0, ratios


@pytest.mark.slow  # 7-9 s of fits on a quiet machine
def test_bootstrap_over_experiments_resamples_the_recordings(client):
    setup = study_setup(RECORDINGS, TRUTH)
    seen = []
    # Seed 1 draws [1, 1, 2] and [0, 0, 2]: an x and a y step in each. A draw of one direction
    # only (seed 4: three y steps) leaves the other axis unidentified and takes ~30 s.
    fit, replicates, method = run_bootstrap(
        lambda: contextlib.nullcontext(client), setup, 2, seed=1, on_outcome=seen.append
    )
    assert method == "experiments"  # the default with several recordings
    assert sorted(o.index for o in seen) == [-1, 0, 1]  # the fit runs beside the replicates
    assert fit.index == -1 and fit.ok and fit.recordings == ()
    picks = [r.recordings for r in replicates]
    assert all(len(p) == 3 and set(p) <= {0, 1, 2} for p in picks)
    assert any(len(set(p)) < 3 for p in picks)  # drawn with replacement (seeded)
    summary = summarize_bootstrap(fit, replicates)
    assert summary["by_status"]["ok"] == 2
    assert all(p["bootstrap_std"] > 0 for p in summary["parameters"].values())
    assert set(summary["parameters"]) == set(fit.estimates)


def test_bootstrap_over_experiments_needs_several_recordings(client):
    setup = study_setup(RECORDINGS[:1], TRUTH)
    with pytest.raises(Exception, match="two or more recordings"):
        run_bootstrap(lambda: contextlib.nullcontext(client), setup, 4, method="experiments")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["multistart", "nope.mcap"], "nope.mcap: no such recording"),
        (["bootstrap", RECORDINGS[0], "--initial", "nope.yaml"], "nope.yaml: no such"),
        (["multistart", RECORDINGS[0], "--model", "one-axis", "--initial", str(TRUTH)],
         "'one-axis' is needed"),
        (["multistart", RECORDINGS[0], "--starts", "0"], "--starts must be >= 1"),
    ],
)  # fmt: skip
def test_study_command_rejects_bad_input_in_one_line(args, message, capsys):
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("hframe-id: error: ") and message in err
    assert err.count("\n") == 1


def test_realistic_fleet_records_realistic_plants(tmp_path, monkeypatch):
    # One step a week keeps this to a few seconds; the plant is what is tested.
    monkeypatch.setattr(synthetic, "EXPERIMENTS", synthetic.EXPERIMENTS[:1])
    manifest = make_fleet(2, 2, seed=3, out=tmp_path / "fleet", plant="realistic")
    doc = yaml.safe_load(manifest.read_text())
    assert doc["defaults"]["model"] == "hframe-8"  # fitted with hframe-8 as before
    aging = yaml.safe_load((tmp_path / "fleet" / "aging.yaml").read_text())
    assert aging["plant"] == "realistic"
    (aged,) = aging["aged"]
    assert aged["kind"] == "belt"
    assert aged["plant_last_week_factor"] == dict.fromkeys(synthetic.REALISTIC_SPRINGS, 0.7)
    # All nine springs x 0.7: the reduced stiffnesses (springs in series) x 0.7 too.
    assert aged["last_week_factor"] == pytest.approx({"k_l": 0.7, "k_r": 0.7, "k_b": 0.7})
    plants = {}
    for fit in doc["fits"]:
        (path,) = fit["recordings"]
        plant = recording_plant(tmp_path / "fleet" / path)
        assert plant is not None, path  # the plant file travels inside the recording
        assert plant.variant == "hframe-20" and plant.constants.current_limit_a == 8.0
        assert plant.actuation_delay_samples == 1 and plant.laser_latency_samples == 2
        assert read_recording(tmp_path / "fleet" / path).variant == "hframe-20"
        plants[(fit["rig"], fit["time"][:10])] = plant.parameters.values
    weeks = sorted({week for _, week in plants})
    ratio = plants[(aged["rig"], weeks[1])]["k_1"] / plants[(aged["rig"], weeks[0])]["k_1"]
    # 0.7 times two weeks' jitter exp(N(0, 0.01)): within 5 % is 3.5 sigma.
    assert ratio == pytest.approx(0.7, rel=0.05)
    (healthy,) = aging["not_aged"]
    ratio = plants[(healthy, weeks[1])]["k_1"] / plants[(healthy, weeks[0])]["k_1"]
    assert ratio == pytest.approx(1.0, rel=0.05)
