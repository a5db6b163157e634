"""Noise levels estimated with the fit: maximum likelihood under model error.

Where the model cannot follow the data (model error 100-1000 x the encoder's step on the
realistic rig), weighing the channels by their sensors' noise lets the most precise sensor
decide everything. Model error also differs between recordings: a step that drives the
amplifier into a current limit the model lacks is followed far worse than a small one. With
an unknown variance per recording e and channel j the likelihood, concentrated on them, is

    L(theta) = sum_e sum_j N_ej / 2 ln(SSR_ej(theta) / N_ej),                     (1)

N_ej the valid samples of channel j in recording e, SSR_ej their residual sum of squares
[SI^2]. Its gradient is that of the weighted least-squares cost 1/2 sum_ej SSR_ej / s_ej^2
with s_ej^2 = SSR_ej / N_ej at the current point, and ln is concave, so that cost, with the
weights of the current point, majorises (1) up to a constant: a step that lowers it lowers L
(majorise-minimise). The levels are floored at the sensors' std (a channel fitted below its
sensor's noise is overfitted, not better known).

One level per channel pooled over the recordings let the recordings the model cannot follow
decide the fit: on dev plant 26 of issue 25 (a 7.4 A current limit that the two 6 V steps hit)
the fit followed those two at the others' expense, and predicted held-out data 4.4 x worse
than the plant's own reduction; with a level per recording and channel, 0.83 x (2026-11-28,
docs/studies/).

Each round is a solve at fixed levels, warm-started from the last; the rounds stop once no
level at a round's end differs from the levels it was solved at by more than
``StrategySettings.noise_rtol``. A round only has to lower the majoriser, not minimise it: it
ends once its last ``GaussNewtonSettings.cost_window`` iterations lowered the majoriser by less
than re-estimating the levels would (``reweighting_gain``), the last round allowed and one after
the levels settled excepted; and every round ends, converged, once they lowered it by less than
the statistical resolution (``_round_interrupt``). Solved to their tolerance, the realistic
plant's first two rounds crawled for 150 iterations each (trust region 5e-3, the cost down by
0.3-1 per iteration of 6,600) and its fit took 120 s; so, 46 s (2026-11-28, docs/studies/).
(Re-setting the levels within a round's solve whenever one moved by 5 %, a rule with no measure
of what either move gains, let a channel that fits badly lower its own weight as it goes: dev
plant 10 ended with phi levels of 0.5 rad, a wrong fit called a success. Measured 2026-11-26,
docs/studies/.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from hframe_id.fitting.problem import FitProblem, build_problem
from hframe_id.fitting.resolution import LIKELIHOOD_RATIO_95
from hframe_id.fitting.shooting import Evaluation, MultipleShooting
from hframe_id.fitting.solver import GaussNewton, SolverState, StageReport
from hframe_id.fitting.stages import exact_stage

if TYPE_CHECKING:  # fit_run imports this module (through estimates)
    from hframe_id.fitting.fit_run import FitRun

REJECTED_ROUND_STAGE = "noise rounds: the stalled last round rejected"
#: How a round that ended for re-weighting (``_round_interrupt``) begins its message.
REWEIGHTED = "re-weighted"


@dataclass(frozen=True)
class ChannelNoise:
    """How a fit weighed one output channel, in the channel's SI unit (m or rad):
    ``sensor_std`` the sensor's noise std (the user's ``channel_std`` or the rig's
    specification), ``weight_std`` the std the fit weighed it with over all recordings (the
    sensor's, or the levels estimated from the residuals, pooled: the rms of the recordings'
    levels weighted by their valid samples), ``recording_std`` the std each recording's
    residuals were divided by, in the order of the recordings (all ``weight_std`` for sensor
    weights), ``residual_rms`` the fit's residual rms over the valid samples;
    ``residual_rms_sensor_std`` that rms in sensor std (dimensionless)."""

    sensor_std: float
    weight_std: float
    residual_rms: float
    residual_rms_sensor_std: float
    recording_std: tuple[float, ...] = ()

    @property
    def differs_by_recording(self) -> bool:
        """Whether the recordings were weighed with levels of their own (not all alike)."""
        return len(set(self.recording_std)) > 1


@dataclass(frozen=True)
class NoiseSettling:
    """How far estimated noise levels were from their fixed point when the rounds ended:
    ``change`` the largest relative change (in log, dimensionless) of a level over the last
    round; ``settled`` whether it was within ``StrategySettings.noise_rtol``."""

    change: float
    settled: bool


@dataclass(frozen=True)
class NoiseReport:
    """How a fit weighed its channels: ``rounds`` of noise estimation (0: by the sensors'
    noise), ``channels`` each output's ``ChannelNoise`` (in the model's output order) and,
    for estimated levels, their ``settling`` (None for sensor weights)."""

    rounds: int
    channels: dict[str, ChannelNoise]
    settling: NoiseSettling | None = None

    @property
    def method(self) -> str:
        """``"estimated"`` (levels estimated from the residuals) or ``"sensor"``."""
        return "estimated" if self.rounds else "sensor"


def unweighted_residuals(ms: MultipleShooting, ev: Evaluation) -> np.ndarray:
    """(W, M, n_y) the residuals of ``ev`` in the channels' SI units (measured - model; 0
    where a sample is not used): the weighted residuals times each window's
    recording's std (``FitProblem.recording_std``)."""
    return ev.residual * ms.problem.recording_std[ms.window_experiment][:, None, :]


def channel_rms(ms: MultipleShooting, ev: Evaluation) -> dict[str, float]:
    """Residual rms of each output channel over its valid samples of every recording [SI]."""
    used = ms.weight > 0
    raw = unweighted_residuals(ms, ev)
    rms = {}
    for j, name in enumerate(ms.problem.output_names):
        n = int(np.count_nonzero(used[:, :, j]))
        rms[name] = (
            math.sqrt(float(np.sum(raw[:, :, j][used[:, :, j]] ** 2)) / n) if n else math.nan
        )
    return rms


def recording_rms(ms: MultipleShooting, ev: Evaluation) -> np.ndarray:
    """(n_experiments, n_y) residual rms [SI] of each output channel over each recording's
    valid samples (NaN where a recording has none of a channel)."""
    used = ms.weight > 0
    squares = unweighted_residuals(ms, ev) ** 2
    n_exp = len(ms.problem.experiments)
    total = np.zeros((n_exp, ms.ny))
    count = np.zeros((n_exp, ms.ny))
    np.add.at(total, ms.window_experiment, np.sum(np.where(used, squares, 0.0), axis=1))
    np.add.at(count, ms.window_experiment, np.sum(used, axis=1))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(total / count)


def estimate_noise(
    run: FitRun,
    state: SolverState,
    recordings,
    sensor_std: np.ndarray,
    first_round: int = 1,
    solver: GaussNewton | None = None,
):
    """Channel noise levels by maximum likelihood, (1), with the fit ``run`` (``FitRun``) on
    ``recordings``, warm-started from ``state`` (every free parameter released; parameters
    held for identifiability are not held again: holding one at its initial value moves the
    others away from the best approximation); levels floored at ``sensor_std`` [SI].

    Rounds of a fit whose levels were estimated already go on from ``first_round`` (> 1:
    none if its levels are settled at ``state``), ``state`` (its ``solver``) counting as
    the converged round before it.

    The rounds end at a round that ends against the stiffness wall
    (``FitRun.against_the_wall``): ``max_substeps``, not the data, decides that point, and
    the strategy restarts off the wall (``fit._off_the_wall``) rather than weigh on there
    (each round at the wall integrates every window with ``max_substeps`` substeps).

    Levels settled after a round that ended for re-weighting (``REWEIGHTED``) get one more
    round, solved to its tolerance: the fit ends on a converged solve.

    A last round that stalls is rejected, as a trust region rejects a step: the fit is the
    last converged round's optimum (a real trajectory at its weights), marked by a
    ``REJECTED_ROUND_STAGE`` stage, with the levels reported as not settled. A round before
    the last that stalls is re-weighted from where it stopped.

    Returns (run, state, solver, rounds, settling): the run of the problem weighted by the
    levels of the last round (its options' ``channel_std`` those levels); ``settling``
    (``NoiseSettling``): the largest relative change (in log) of a level over the last
    round, and whether it met ``StrategySettings.noise_rtol``.
    """
    state.active = np.ones(len(run.problem.free), dtype=bool)
    strategy = run.options.strategy
    stages = run.stages
    gn = solver
    rounds = first_round - 1
    accepted = None if solver is None else (run, state, solver, rounds)
    for rounds in range(first_round, strategy.max_noise_rounds + 1):
        levels = noise_levels(run.ms, state, sensor_std)
        change = _change(levels, run.problem.recording_std)
        settled = rounds > 1 and change <= strategy.noise_rtol and stages[-1].converged
        if settled and not stages[-1].message.startswith(REWEIGHTED):
            rounds -= 1
            break
        run = _weighted(recordings, run, levels)
        label = _round_label(rounds, run.problem.output_names, levels)
        # Settled after a round that ended for re-weighting, or the last round allowed: one
        # solved to its tolerance.
        last = settled or rounds == strategy.max_noise_rounds
        state, gn = warm_solve(run, state, label, True, None if last else sensor_std)
        if stages[-1].converged:
            accepted = (run, state, gn, rounds)
        if run.against_the_wall(state.theta):
            break
    if not stages[-1].converged and accepted is not None:
        run, state, gn, kept = accepted
        stages.append(_rejected_round_report(stages[-1], kept, run.ms, state))
    change = _change(noise_levels(run.ms, state, sensor_std), run.problem.recording_std)
    return run, state, gn, rounds, NoiseSettling(change, change <= strategy.noise_rtol)


def _change(levels: np.ndarray, weight_std: np.ndarray) -> float:
    """The largest relative change (in log) between two sets of levels."""
    return float(np.max(np.abs(np.log(levels / weight_std))))


def _weighted(recordings, run: FitRun, levels: np.ndarray) -> FitRun:
    """``run`` with its problem, transcription and options weighing each recording's
    channels by its row of ``levels`` [SI] (``FitOptions.recording_std``), and reporting
    each channel's level over all recordings (``channel_std``: the rms of the recordings'
    levels, weighted by their valid samples)."""
    names = run.problem.output_names
    counts = np.array([e.valid.sum(axis=0) for e in run.problem.experiments], dtype=float)
    pooled = np.sqrt(np.sum(counts * levels**2, axis=0) / np.maximum(counts.sum(axis=0), 1.0))
    options = replace(
        run.options,
        channel_std=dict(zip(names, pooled.tolist(), strict=True)),
        recording_std={name: tuple(levels[:, j].tolist()) for j, name in enumerate(names)},
    )
    problem = build_problem(recordings, run.problem.initial, options)
    ms = MultipleShooting(problem, transcription=options.transcription_options)
    return replace(run, problem=problem, ms=ms, options=options)


def noise_levels(ms, state: SolverState, sensor_std: np.ndarray) -> np.ndarray:
    """(n_experiments, n_y) the next round's level per recording and channel [SI]: the
    residual rms at ``state``, floored at the sensor's std (the weights' std where a
    recording has no valid sample of a channel)."""
    return _levels_at(ms, state.evaluation, sensor_std)


def _levels_at(ms: MultipleShooting, ev: Evaluation, sensor_std: np.ndarray) -> np.ndarray:
    """``noise_levels`` at the evaluation ``ev``."""
    rms = recording_rms(ms, ev)
    weight_std = ms.problem.recording_std
    return np.maximum(np.where(np.isfinite(rms), rms, weight_std), sensor_std)


def reweighting_gain(ms: MultipleShooting, ev: Evaluation, sensor_std: np.ndarray) -> float:
    """How much re-estimating the levels at ``ev`` would lower the round's majoriser of (1)
    [chi^2 / 2, likelihood units]: sum_ej SSR_ej / (2 s_ej^2) + N_ej ln s_ej at the levels the
    round weighs with, s = ``FitProblem.recording_std``, minus the same at the levels
    ``noise_levels`` would set, s' (its minimiser over s >= the sensors' std). >= 0; the
    round's own iterations lower the first term at fixed s."""
    used = ms.weight > 0
    counts = np.zeros((len(ms.problem.experiments), ms.ny))
    np.add.at(counts, ms.window_experiment, np.sum(used, axis=1))
    rms = np.nan_to_num(recording_rms(ms, ev))
    ssr = counts * rms**2

    def majoriser(levels: np.ndarray) -> float:
        return float(np.sum(ssr / (2 * levels**2) + counts * np.log(levels)))

    return majoriser(ms.problem.recording_std) - majoriser(_levels_at(ms, ev, sensor_std))


def _round_interrupt(ms: MultipleShooting, sensor_std: np.ndarray | None):
    """A round's ``GaussNewton.run`` interrupt. It ends the round, converged, once its last
    iterations lowered the majoriser by less than the statistical resolution
    (``LIKELIHOOD_RATIO_95``: a likelihood-ratio test at 95 %; over the same 10 iterations
    the tolerance 1e-6 relative of the other stages is 0.05-0.5 of it at these costs,
    10^4-10^5; a change of 1.92 is, by (1), 2e-4 relative in the rms of 10^4 samples, 2e-3
    if all of it falls on one 1,000-sample record's channel); with the sensors' std
    ``sensor_std`` [SI] (another round may follow), also once they lowered it by less than
    re-estimating the levels would
    (``reweighting_gain``; message ``REWEIGHTED``). The rounds are a majorise-minimise
    iteration: each only has to lower the majoriser, and one crawling along a valley at fixed
    levels spends its time where the next levels gain more, or where nothing the data can tell
    is gained (the realistic plant's first rounds: 150 iterations, 0.3-1 per iteration of
    6,600; dev plant 57's limited fit: a last round at 2 s and 0.03 per iteration).
    Iterations over which the cost rose (the defects of a solve from new nodes closing: the
    solve from rest) end nothing."""

    def interrupt(ev: Evaluation, decrease: float) -> str | None:
        if decrease < 0:  # the cost rose as the defects closed (a solve from new nodes)
            return None
        if decrease < LIKELIHOOD_RATIO_95:
            return (
                f"converged: the last iterations lowered the criterion by {decrease:.4g}, less "
                f"than the statistical resolution {LIKELIHOOD_RATIO_95}"
            )
        if sensor_std is None:
            return None
        gain = reweighting_gain(ms, ev, sensor_std)
        if gain > decrease:
            return (
                f"{REWEIGHTED}: new levels lower the criterion by {gain:.4g}, more than the "
                f"last iterations did ({decrease:.4g})"
            )
        return None

    return interrupt


def _round_label(rounds: int, names, levels: np.ndarray) -> str:
    """A noise round's stage name, with each channel's range of levels over the recordings."""

    def span(column: np.ndarray) -> str:
        low, high = float(column.min()), float(column.max())
        return f"{low:.3g}" if math.isclose(low, high, rel_tol=1e-3) else f"{low:.3g}-{high:.3g}"

    shown = ", ".join(f"{name} {span(levels[:, j])}" for j, name in enumerate(names))
    return f"noise round {rounds} (std {shown})"


def _rejected_round_report(stalled: StageReport, kept: int, ms, state) -> StageReport:
    """The stage that records a stalled last round rejected and round ``kept``'s optimum
    taken as the fit."""
    return StageReport.verdict(
        REJECTED_ROUND_STAGE,
        stalled,
        f"the last noise round did not converge ({stalled.message}); the fit is "
        f"noise round {kept}'s optimum, its noise levels not settled",
        state.evaluation.cost,
        float(np.max(np.abs(ms.defects(state.evaluation, state.nodes)), initial=0)),
    )


def warm_solve(
    run: FitRun,
    start: SolverState,
    label: str,
    estimated: bool = False,
    sensor_std: np.ndarray | None = None,
):
    """Every window of ``run``'s transcription, exact continuity, from ``start``'s nodes and
    parameters, monotone (no step may raise the merit: a warm start is kept, not thrown
    away by free steps), its stage ``label`` appended to ``run.stages``. With estimated
    levels a stall counts as converged only with its defects at ``defect_tol`` (or closed
    by simulation), see ``GaussNewton.run``. A solve at ``estimated`` levels (a noise
    round) ends at the statistical resolution; one that another round may follow passes the
    sensors' std ``sensor_std`` [SI] and also ends once re-weighting gains more
    (``_round_interrupt``). Returns (state, solver)."""
    ms = run.ms.uniform()
    gn = run.solver(ms, freeze_sloppy=True)
    state = SolverState(start.nodes.copy(), start.theta.copy(), start.active.copy())
    run.stages.append(
        exact_stage(
            gn,
            state,
            label,
            run.options.solver_options,
            cost_rtol=run.options.strategy.warm_cost_rtol,
            radius=0.5,
            watchdog=False,
            stall_defect_tol=run.options.defect_tol,
            interrupt=_round_interrupt(ms, sensor_std) if estimated else None,
        )
    )
    run.add_evaluations(gn.evaluations)
    return state, gn


def noise_report(
    problem: FitProblem,
    sensor_std: np.ndarray,
    rms: dict[str, float],
    rounds: int,
    settling: NoiseSettling | None,
) -> NoiseReport:
    """Per channel: the sensor's noise std ``sensor_std`` [SI], the std the fit weighed with,
    and the residual rms ``rms`` [SI] also in sensor std (the mismatch statement of the
    report); for estimated levels (``rounds`` > 0) also how far they were from their fixed
    point (``settling``)."""
    return NoiseReport(
        rounds=rounds,
        channels={
            name: ChannelNoise(
                sensor_std=float(sensor_std[j]),
                weight_std=float(problem.channel_std[j]),
                recording_std=tuple(float(v) for v in problem.recording_std[:, j]),
                residual_rms=rms[name],
                residual_rms_sensor_std=rms[name] / float(sensor_std[j]),
            )
            for j, name in enumerate(problem.output_names)
        },
        settling=settling if rounds else None,
    )
