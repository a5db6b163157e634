"""One fit inside one box (``fitting.local_fit``): the rules between its stages, each on
hand-made inputs. The misfit judgement, the coordinates no output measures
(``fitting.unmeasured``) and the strategy's list of stages; the identifiability holds:
test_holds.py; the stages themselves: test_stages.py; whole fits: integration/."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from hframe_id.fitting import FitOptions, local_fit, unmeasured
from hframe_id.fitting.box_opening import BoxOpening
from hframe_id.fitting.fit_run import Fitted
from hframe_id.fitting.problem import build_problem
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording

MODELS = Path(__file__).resolve().parents[2] / "models"

# --- the misfit judgement -------------------------------------------------------------


def _judged(result, estimated=False):
    """``result`` judged on two windows of two recordings weighed at twice and four times the
    sensors' noise, with residuals of 3 and 1.5 (in those units) in every used sample and 100
    in an unused one: the residual rms in sensor std is 3 x 2 = 1.5 x 4 = 6."""
    residual = np.full((2, 3, 2), 3.0)
    residual[1] = 1.5
    residual[1, 2, 0] = 100.0
    weight = np.ones_like(residual)
    weight[1, 2, 0] = 0.0
    problem = SimpleNamespace(recording_std=np.array([[2.0, 2.0], [4.0, 4.0]]))
    ms = SimpleNamespace(weight=weight, problem=problem, window_experiment=np.array([0, 1]))
    state = SimpleNamespace(evaluation=SimpleNamespace(residual=residual))
    return local_fit._misfit_judged(result, ms, state, np.array([1.0, 1.0]), estimated)


def test_the_misfit_is_the_rms_over_used_samples_in_sensor_noise_units(small_result):
    judged = _judged(small_result())
    assert judged.diagnostics.residual_rms_sensor_std == pytest.approx(6.0, rel=1e-12)


def test_a_fit_beyond_the_default_misfit_limit_fails_saying_so(small_result):
    judged = _judged(small_result())
    assert not judged.success
    assert judged.message.startswith(
        "converged to a poor fit: residual rms 6 x the sensors' noise (limit 5, the default)"
    )


@pytest.mark.parametrize(
    ("max_misfit", "estimated", "success"),
    [(10.0, False, True), (4.0, False, False), (None, True, True), (4.0, True, False)],
)
def test_the_users_limit_applies_and_estimated_noise_levels_have_none_by_default(
    small_result, max_misfit, estimated, success
):
    options = FitOptions(free=("k_l",), max_misfit=max_misfit)
    judged = _judged(small_result(options=options), estimated)
    assert judged.success is success
    if not success:
        assert "FitOptions.max_misfit / --max-misfit" in judged.message


def test_a_failed_fit_keeps_its_message_and_gets_its_misfit(small_result):
    judged = _judged(small_result(success=False, message="stalled"))
    assert (judged.success, judged.message) == (False, "stalled")
    assert judged.diagnostics.residual_rms_sensor_std == pytest.approx(6.0, rel=1e-12)


# --- coordinates no output measures ----------------------------------------------------


@pytest.fixture(scope="module")
def one_axis_shooting():
    """The one-axis model's transcription of a short 5 V pulse (Table 2.3)."""
    params = load_parameter_file(MODELS / "one-axis-table2.3.yaml")
    u = np.zeros((200, 1))
    u[20:120] = 5.0
    recording = simulate_recording(params, u, seed=1)
    problem = build_problem([recording], params, FitOptions().for_model("one-axis"))
    return problem, MultipleShooting(problem)


def test_every_h_frame_coordinate_is_measured(shooting_setup):
    """hframe-8: encoders on both motors, lasers on x and y."""
    problem, ms, _, _ = shooting_setup
    assert unmeasured.measured_coordinates(ms).all()
    assert not unmeasured.unmeasured_coordinates(ms)
    assert unmeasured.springs_at_unmeasured_coordinates(problem, ms) == []


def test_the_one_axis_idler_is_unmeasured_and_held_by_k2_and_k3(one_axis_shooting):
    """One-axis (section 2.2): outputs phi1 (encoder) and x (laser), none on the idler phi3;
    the belt sections on either side of the idler, k2 (cart-idler) and k3 (idler-motor),
    pull on it, k1 (motor-cart) does not."""
    problem, ms = one_axis_shooting
    names = [c.name for c in ms.model.coordinates]
    measured = dict(zip(names, unmeasured.measured_coordinates(ms).tolist(), strict=True))
    assert measured == {"phi1": True, "x": True, "phi3": False}
    assert unmeasured.unmeasured_coordinates(ms)
    springs = unmeasured.springs_at_unmeasured_coordinates(problem, ms)
    assert [problem.free_names[i] for i in springs] == ["k2", "k3"]


# --- the strategy: its stages in order ---------------------------------------------------


def _run(noise="auto", state_prepass=True, rms=1.0, last="all windows"):
    """A stand-in run: its options, a transcription whose residual rms [noise std] is
    ``rms``, and stages that ended with ``last``."""
    options = FitOptions(noise=noise, state_prepass=state_prepass)
    ms = SimpleNamespace(residual_rms=lambda cost: rms)
    stages = [SimpleNamespace(name=last, converged=True)]
    return SimpleNamespace(options=options, ms=ms, stages=stages)


def _names(stages):
    return [type(stage).__name__ for stage in stages]


@pytest.mark.parametrize(
    ("unmeasured_coordinate", "state_prepass", "box", "names", "prepasses"),
    [
        (False, True, None, ["Attempts", "NoiseLevels", "ReplayedRest"], (False,)),
        (
            False,
            True,
            BoxOpening(10.0, 2),
            ["Attempts", "OnTheBox", "NoiseLevels", "ReplayedRest", "OpenedBox"],
            (False,),
        ),
        (
            True,
            True,
            None,
            ["Attempts", "UnmeasuredRestarts", "NoiseLevels", "ReplayedRest"],
            (True, False),
        ),
        (True, False, None, ["Attempts", "NoiseLevels", "ReplayedRest"], (False,)),
    ],
)
def test_the_strategy_lists_its_stages_for_the_model_and_the_box(
    monkeypatch, unmeasured_coordinate, state_prepass, box, names, prepasses
):
    """A coordinate no output measures (one-axis: the idler) adds the pre-pass attempt and
    the restarts along its springs, unless the pre-pass is off; a fit whose box may open
    stops on it before the noise rounds, or goes on in the opened box after them."""
    found = [1] if unmeasured_coordinate else []
    monkeypatch.setattr(local_fit, "unmeasured_coordinates", lambda ms: found)
    stages = local_fit.strategy(_run(state_prepass=state_prepass), box)
    assert _names(stages) == names
    assert stages[0].prepasses == prepasses


def _standing(run, deferred=False):
    best = Fitted(SimpleNamespace(evaluation=SimpleNamespace(cost=1.0)), "solver", None)
    return local_fit.Standing(run, [], np.ones(2), best=best, deferred=deferred)


def test_restarts_are_not_run_where_the_stages_deferred_to_the_noise_rounds(monkeypatch):
    calls = []
    monkeypatch.setattr(
        local_fit, "restarts_along_unmeasured_springs", lambda run, best: calls.append(best)
    )
    at = _standing(_run(), deferred=True)
    assert local_fit.UnmeasuredRestarts()(at) is at and calls == []
    local_fit.UnmeasuredRestarts()(_standing(_run()))
    assert len(calls) == 1


@pytest.mark.parametrize(
    ("noise", "rms", "deferred", "estimated"),
    [
        ("sensor", 10.0, True, False),  # the sensors' levels, whatever the misfit
        ("auto", 1.0, False, False),  # at the noise level: nothing to estimate
        ("auto", 10.0, False, True),  # above StrategySettings.mismatch_rms (3)
        ("auto", 1.0, True, True),  # the stages deferred to the rounds
        ("estimate", 1.0, False, True),
    ],
)
def test_noise_levels_are_estimated_where_the_options_and_the_misfit_ask(
    monkeypatch, noise, rms, deferred, estimated
):
    run = _run(noise=noise, rms=rms)
    run.statistics = lambda gn, state: "statistics"
    rounds = []

    def estimate_noise(run, state, recordings, sensor_std):
        rounds.append(state)
        return run, state, "solver", 3, "settling"

    monkeypatch.setattr(local_fit, "estimate_noise", estimate_noise)
    at = local_fit.NoiseLevels()(_standing(run, deferred))
    assert bool(rounds) is estimated
    assert (at.rounds, at.settling) == ((3, "settling") if estimated else (0, None))


@pytest.mark.parametrize(("on_the_box", "opens"), [(True, True), (True, False), (False, True)])
def test_a_fit_on_a_box_that_opens_ends_with_its_result_as_it_stands(on_the_box, opens):
    result = SimpleNamespace(diagnostics=SimpleNamespace(at_default_box=("k_l",) * on_the_box))
    run = _run()
    run.result = lambda best: result
    box = SimpleNamespace(
        opened=lambda options, ended: (
            options if ended.diagnostics.at_default_box and opens else None
        )
    )
    at = local_fit.OnTheBox(box)(_standing(run))
    assert (at.ended is result) is (on_the_box and opens)


def _stage_to(theta, called):
    """A stage that moves the fit to ``theta`` (a 1-vector), noting that it ran."""

    def stage(at):
        called.append(theta)
        state = SimpleNamespace(theta=np.array([theta]))
        return local_fit.Standing(at.run, at.recordings, at.sensor_std, best=Fitted(state, 0, 0))

    return stage


def test_a_stage_ending_against_the_stiffness_wall_ends_the_fit_there(monkeypatch):
    """The stages after one that ends against the wall (here, at theta 1) do not run: the
    fit ends at that stage's point, which the strategy restarts off the wall."""
    run = _run()
    run.problem = SimpleNamespace(channel_std=np.ones(2))
    run.against_the_wall = lambda theta: ("J_M1",) if theta[0] == 1.0 else ()
    called = []
    stages = tuple(_stage_to(t, called) for t in (0.0, 1.0, 2.0))
    monkeypatch.setattr(local_fit, "_started_run", lambda *args, **kwargs: run)
    monkeypatch.setattr(local_fit, "strategy", lambda run, box: stages)
    monkeypatch.setattr(local_fit, "_finished", lambda at: at.best.state.theta[0])
    assert local_fit.fit_in_box([], None, run.options) == 1.0
    assert called == [0.0, 1.0]
    run.against_the_wall = lambda theta: ()
    assert local_fit.fit_in_box([], None, run.options) == 2.0


@pytest.mark.parametrize(("rounds", "interrupted"), [(0, False), (3, True), (10, False)])
def test_the_solve_from_rest_ends_for_reweighting_only_where_rounds_follow_it(
    monkeypatch, rounds, interrupted
):
    """Sensor weights (no rounds) or rounds at ``max_noise_rounds`` (10): the solve from the
    replay's rest state is the fit's last (at estimated levels, it ends at the statistical
    resolution as the last round does); between rounds it is one, given the sensors' std to
    end once re-weighting gains more."""
    given = []

    def solve_from_rest(run, best, recordings, estimated=False, sensor_std=None):
        given.append((estimated, sensor_std))
        return run, best

    monkeypatch.setattr(local_fit, "replays_rest", lambda run: True)
    monkeypatch.setattr(local_fit, "solve_from_replayed_rest", solve_from_rest)
    monkeypatch.setattr(local_fit, "estimate_noise", lambda *args: (args[0], *"sgrn"))
    at = replace(_standing(_run()), rounds=rounds)
    local_fit.ReplayedRest()(at)
    estimated, sensor_std = given[0]
    assert estimated is (rounds > 0)
    assert (sensor_std is at.sensor_std) is interrupted
