"""The unseen-plants study's drawing of plants, criteria and command line, without fitting (a
fit takes 10-120 s; ``python -m studies.unseen_plants`` runs them)."""

import json
import math

import numpy as np
import pytest

from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording
from hframe_id.rig.realistic import NOT_DRAWN, record_realistic, shipped_plant
from studies import unseen_plants as study
from studies.mismatch import HELD_OUT, STEP_PROTOCOLS, TABLE_4_2
from studies.mismatch_effects import record_smooth
from studies.unseen_plants import (
    BELTS,
    COULOMB,
    DEV_SEEDS,
    GAINS,
    MASSES,
    NAMED,
    TEST_SEEDS,
    VISCOUS,
    PlantDraw,
    TrialError,
    UnseenTrial,
    build_plant,
    checked_reference,
    draw_plant,
    error_of,
    free_run_residuals,
    motor_angle_rms,
    passes_held_out,
    passes_training,
    summary_lines,
    trial_document,
    weighted_cost,
)

#: Plants drawn for the envelope checks: both splits (200 draws, < 1 s).
SEEDS = (*DEV_SEEDS, *TEST_SEEDS)


@pytest.fixture(scope="module")
def draws():
    return [draw_plant(s) for s in SEEDS]


@pytest.fixture(scope="module")
def shipped():
    return shipped_plant("hframe-20").parameters.values


def test_every_hframe20_parameter_is_drawn_or_held(shipped):
    groups = (COULOMB, VISCOUS, BELTS, MASSES, GAINS)
    grouped = [name for group in groups for name in group]
    assert len(grouped) == len(set(grouped)), "a parameter in two groups"
    held = set(NOT_DRAWN) - {"g_1"}  # the envelope draws g_1 too
    assert set(grouped) | held == set(shipped)
    assert not set(grouped) & held


def test_a_seed_gives_the_same_plant_and_seeds_differ():
    assert draw_plant(7) == draw_plant(7)
    assert draw_plant(7) != draw_plant(8)
    assert build_plant(draw_plant(7)).parameters.values == (
        build_plant(draw_plant(7)).parameters.values
    )


def test_draws_stay_in_the_envelope(draws):
    for d in draws:
        assert 0.4 <= d.stiffness <= 2.5
        assert all(0.9 <= b <= 1.1 for b in d.belts)
        assert all(0.5 <= m <= 2.0 for m in d.masses)
        if d.linear:
            continue
        assert d.coulomb == 0 or 0.01 <= d.coulomb <= 10
        assert 0.01 <= d.viscous <= 10
        assert all(0.8 <= g <= 1.1 for g in d.gains)
        assert d.current_limit_a is None or 6 <= d.current_limit_a <= 12
        assert all(n in (0, 1, 2, 3) for n in d.latencies)
        if d.friction == "smooth":
            assert (d.static_to_coulomb_ratio, d.stribeck) == (1.0, 1.0)
        else:
            assert d.friction == "stick-slip"
            assert 1.0 <= d.static_to_coulomb_ratio <= 1.5 and 0.5 <= d.stribeck <= 2.0


def test_branch_shares_are_near_the_envelopes(draws):
    # 200 draws: a binomial share p has std sqrt(p (1 - p) / 200) <= 0.036; 4 std of slack.
    realistic = [d for d in draws if not d.linear]
    shares = {
        "linear": (np.mean([d.linear for d in draws]), 0.15),
        "no Coulomb": (np.mean([d.coulomb == 0 for d in realistic]), 0.15),
        "no limit": (np.mean([d.current_limit_a is None for d in realistic]), 1 / 3),
        "stick-slip": (np.mean([d.friction == "stick-slip" for d in realistic]), 0.5),
    }
    for name, (share, expected) in shares.items():
        assert abs(share - expected) < 4 * 0.036, name
    for latency in range(3):
        assert {d.latencies[latency] for d in realistic} == {0, 1, 2, 3}


def test_every_drawn_plant_has_a_valid_finite_reduction(draws):
    for d in draws:
        plant = build_plant(d)
        reference = checked_reference(plant)
        assert reference.variant == "hframe-8"
        assert all(math.isfinite(v) for v in reference.values.values())


def test_a_plant_applies_its_factors(shipped):
    d = next(d for d in map(draw_plant, DEV_SEEDS) if not d.linear and d.coulomb > 0)
    plant = build_plant(d)
    v = plant.parameters.values
    assert v["tau_c1"] == pytest.approx(shipped["tau_c1"] * d.coulomb)
    assert v["b_bridge"] == pytest.approx(shipped["b_bridge"] * d.viscous)
    assert v["k_9"] == pytest.approx(shipped["k_9"] * d.stiffness * d.belts[8])
    assert v["J_8"] == pytest.approx(shipped["J_8"] * d.masses[MASSES.index("J_8")])
    assert (v["g_1"], v["g_2"]) == d.gains
    assert v["r"] == shipped["r"] and v["l_3"] == shipped["l_3"]
    c = plant.constants
    assert c.static_to_coulomb_ratio == d.static_to_coulomb_ratio
    assert c.current_limit_a == (math.inf if d.current_limit_a is None else d.current_limit_a)
    assert (
        plant.actuation_delay_samples,
        plant.encoder_latency_samples,
        plant.laser_latency_samples,
    ) == d.latencies
    assert plant.position_dependent_stiffness


def test_coulomb_zero_reaches_the_reduction():
    d = next(d for d in map(draw_plant, DEV_SEEDS) if not d.linear and d.coulomb == 0)
    plant = build_plant(d)
    assert all(plant.parameters.values[n] == 0 for n in COULOMB)
    reference = checked_reference(plant)
    assert all(reference.values[n] == 0 for n in ("tau_cM1", "tau_cM2", "F_c_cart", "F_c_bridge"))


def test_a_linear_plant_is_table_3_1_with_its_shape_factors():
    d = next(d for d in map(draw_plant, DEV_SEEDS) if d.linear)
    plant = build_plant(d)
    v = plant.parameters.values
    assert all(v[n] == 0 for n in COULOMB)
    assert v["b_cart"] == 23.2224 and v["g_2"] == 1.0  # Table 3.1's, not drawn
    assert v["k_1"] == pytest.approx(17810.0 * d.stiffness * d.belts[0])
    assert plant.constants.current_limit_a == math.inf
    assert not plant.position_dependent_stiffness
    assert study.recorder_for(d) is record_smooth
    assert d.describe().startswith("linear Table 3.1")


def test_a_linear_draw_refuses_realistic_effects():
    with pytest.raises(Exception, match="only stiffness and mass factors"):
        PlantDraw("bad", linear=True, current_limit_a=None, latencies=(1, 0, 0), friction="smooth")


def test_the_named_plants(shipped):
    assert set(NAMED) == {"linear", "lubricated", "worn", "heavy"}
    plants = {name: build_plant(d) for name, d in NAMED.items()}
    for plant in plants.values():
        checked_reference(plant)
    linear = plants["linear"].parameters.values
    assert linear["k_1"] == 17810.0 and linear["tau_c1"] == 0.0
    assert study.recorder_for(NAMED["linear"]) is record_smooth
    lubricated = plants["lubricated"]
    assert lubricated.parameters.values["F_c_bridge"] == pytest.approx(1.9 * 0.03)
    assert lubricated.parameters.values["b_bridge"] == shipped["b_bridge"]
    assert lubricated.constants.current_limit_a == math.inf
    worn = plants["worn"].parameters.values
    assert worn["k_5"] == pytest.approx(shipped["k_5"] * 0.55)
    assert worn["tau_c3"] == pytest.approx(shipped["tau_c3"] * 3)
    assert worn["B_2"] == pytest.approx(shipped["B_2"] * 3)
    assert plants["worn"].constants.current_limit_a == 8.0
    heavy = plants["heavy"]
    assert heavy.parameters.values["M_cart"] == pytest.approx(shipped["M_cart"] * 1.8)
    assert heavy.parameters.values["M_bridge"] == shipped["M_bridge"]
    assert heavy.parameters.values["F_c_cart"] == pytest.approx(shipped["F_c_cart"] * 0.5)
    assert heavy.constants.current_limit_a == 12.0
    for name in ("lubricated", "worn", "heavy"):
        assert study.recorder_for(NAMED[name]) is record_realistic
        assert plants[name].actuation_delay_samples == 1
        assert plants[name].laser_latency_samples == 2


def test_weighted_cost_and_motor_angle_rms_by_hand():
    residuals = {
        "phi1": np.array([1.0, -1.0]),
        "phi2": np.array([3.0]),
        "x": np.array([2e-6, 0.0]),
        "y": np.array([]),
    }
    std = {"phi1": 1.0, "phi2": 2.0, "x": 1e-6, "y": 5e-6}
    assert weighted_cost(residuals, std) == pytest.approx(0.5 * (1 + 1 + 2.25 + 4))
    assert motor_angle_rms(residuals) == pytest.approx(math.sqrt(11 / 3))
    with pytest.raises(KeyError):
        weighted_cost(residuals, {"phi1": 1.0})  # a channel without a noise level


def test_pass_thresholds():
    assert passes_training(1.05, 1.0) and not passes_training(1.06, 1.0)
    assert passes_held_out(1.5, 1.0) and not passes_held_out(1.51, 1.0)
    assert not passes_training(math.nan, 1.0) and not passes_held_out(math.nan, 1.0)


def test_residuals_of_the_truth_are_the_sensor_noise():
    # A 0.3 s hframe-8 step recorded by the plain sim rig from the shipped plant's reduction
    # and replayed through it: the laser residuals are the 5 um sensor noise (the encoders
    # quantize), so each laser term of the cost is about N / 2.
    reference = shipped_plant("hframe-20").reference()
    volts = STEP_PROTOCOLS[1].table(1e-3)[:300]
    recording = simulate_recording(reference, volts, seed=3)
    residuals = free_run_residuals(reference, [recording, recording])
    model = build_model("hframe-8")
    assert set(residuals) == {s.name for s in model.outputs}
    assert residuals["phi1"].size == 600
    x_cost = weighted_cost({"x": residuals["x"]}, {"x": 5e-6})
    # chi-square with ~600 degrees of freedom / 2: 300 +/- 17; the rest start slightly off.
    assert 200 < x_cost < 420
    assert motor_angle_rms(residuals) < 1e-3


def test_travel_of_a_plant_that_runs_away():
    # The shipped plant's steps move the cart a few cm; seed 0 (friction x0.01) runs into the
    # belt end (0.35 m), where its position-dependent stiffness blows up.
    step = [HELD_OUT["5V x step"]]
    assert 0.01 < study.plant_travel_m(shipped_plant("hframe-20"), step) < study.TRAVEL_M
    assert study.plant_travel_m(build_plant(draw_plant(0)), step) > study.TRAVEL_M


def _trial(label="seed 1", **fields) -> UnseenTrial:
    return UnseenTrial(draw=PlantDraw(label), split="dev", **fields)


def test_error_of_names_the_innermost_frame():
    def fail():
        raise ValueError("bad step\nsecond line")

    try:
        fail()
    except ValueError as err:
        error = error_of(err, "fit")
    assert (error.stage, error.type, error.message) == ("fit", "ValueError", "bad step")
    assert error.where.startswith("tests/studies/test_unseen_plants.py:")
    assert error.where.endswith("(fail)") and error.where_own == error.where


def test_a_trial_that_raises_is_a_row(monkeypatch):
    def broken_fit(*args, **kwargs):
        raise RuntimeError("solver exploded")

    monkeypatch.setattr(study, "plant_travel_m", lambda *args: 0.1)
    monkeypatch.setattr(study, "training_recordings", lambda *args: [])
    monkeypatch.setattr(study, "fit_recordings", broken_fit)
    trial = study.run_trial(NAMED["heavy"], "named")
    assert trial.error.stage == "fit" and trial.error.type == "RuntimeError"
    assert "(broken_fit)" in trial.error.where_own
    assert trial.success is None and math.isfinite(trial.wall_time_s)
    assert not trial.passes_training and not trial.passes_held_out
    assert "TRACEBACK in fit" in study.trial_line(trial)


def test_summary_counts_and_json_rows():
    ok = _trial(
        success=True, wall_time_s=10.0, cost=(1.0, 1.0), held_out_rms_rad=(1.0, 1.0), travel_m=0.1
    )
    off = _trial(
        success=False, wall_time_s=30.0, cost=(2.0, 1.0), held_out_rms_rad=(1.0, 1.0), travel_m=0.4
    )
    crashed = _trial(wall_time_s=5.0, error=TrialError("fit", "E", "m", "a:1", "b:2"))
    exited = _trial(error=TrialError("process", "BrokenProcessPool", "m", "?", "?"))
    lines = summary_lines([ok, off, crashed, exited])
    assert lines[0] == (
        "plants 4: training criterion pass 1/4, held-out pass 2/4, both 1/4; success 1/4; "
        "tracebacks 1, exits 1"
    )
    assert lines[1] == (
        "within the +/-0.25 m travel 1/4: training criterion pass 1, held-out pass 1, both 1"
    )
    assert lines[2] == "fit wall time: median 10.0 s, max 30.0 s (3 fits)"
    assert "travel 0.4 m (LEAVES TRAVEL)" in study.trial_line(off)
    assert "travel 0.1 m training" in study.trial_line(ok)
    assert "travel" not in study.trial_line(crashed)
    doc = json.loads(json.dumps(trial_document(crashed), allow_nan=False))
    assert doc["cost"] == [None, None] and doc["error"]["where_own"] == "b:2"
    assert doc["draw"]["current_limit_a"] == 8.0 and doc["plant"] == crashed.draw.describe()


def test_test_seeds_are_refused_without_the_flag(capsys):
    assert study.main(["--seeds", "3", "1042"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "1042" in err and "--test-split" in err


def test_help_documents_every_option(capsys):
    with pytest.raises(SystemExit) as exit_:
        study.main(["--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    for option in ("--seeds", "--named", "--test-split", "--jobs", "--json"):
        assert option in text
    with pytest.raises(SystemExit):
        study.main(["--jobs", "0"])


def test_selected_tasks_default_to_a_whole_split():
    parser = study.make_parser()
    assert study.selected_tasks(parser.parse_args([])) == [("seed", s) for s in DEV_SEEDS]
    tasks = study.selected_tasks(parser.parse_args(["--test-split"]))
    assert tasks == [("seed", s) for s in TEST_SEEDS]
    tasks = study.selected_tasks(parser.parse_args(["--named", "worn", "--seeds", "4"]))
    assert tasks == [("named", "worn"), ("seed", 4)]


def test_seeded_starts_are_reproducible_and_within_the_spread():
    from studies.seeded_starts import SPREAD, reached_best, seeded_start

    table = load_parameter_file(TABLE_4_2)
    free = ("k_l", "M_cart", "F_c_cart")
    first, again = seeded_start(table, free, 3), seeded_start(table, free, 3)
    assert first.values == again.values
    for name in free:
        factor = first.values[name] / table.values[name]
        assert SPREAD[0] <= factor <= SPREAD[1]
    assert first.values["k_r"] == table.values["k_r"]
    assert reached_best([1.0, 1.005, 1.02, float("nan")]) == 2
