"""The fit's last solve: each record at rest from the state ``validate`` replays it from.

The stages start a record at rest with its velocities zero and its belts unstretched, and
estimate its belt-free position (``TranscriptionOptions.rest_start`` "rigid": the path
from there is smoother than from a fixed state; fixing it throughout gave four wrong
successes of twelve on the dev plants, docs/studies/2026-11-26-rest-states.md). Under model
error the estimated position drifts from where the record stands: by 48 um and 2.4e-3 rad
on the linear hframe-20 plant of issue 25, where the written file then replayed 4,800
concentrated units worse than the fit had reported (-179,887 against -184,684), worse than
the point the fit began from. So once the stages have converged, the fit is solved once more
with every record at rest started from the replay's rest state (``rest_start`` "replay",
``fitting.rest_state.rest_state``: nothing estimated), warm from where they ended, at the same
weights. What the fit then reports, residuals and criterion, is what ``validate``
reproduces from the written file (issue 25, item 1).

A last solve that stops unconverged (under model error it can crawl: on the lubricated plant
of issue 25, 150 iterations of trust-region steps of 1e-4-3e-3, the cost still falling by
~0.1 chi^2 / 2 per iteration) is judged by what it is for: both its end and the stages' end
are replayed from rest as ``validate`` replays them (``known_points.simulation_criterion``,
at the fit's weights). Its end is kept if it replays better, saying it stopped unconverged
(there: 565 concentrated units better than the stages' end, which a rejection had written);
otherwise it is rejected, as a stalled noise round is: the fit keeps the stages' end (its
belt-free positions estimated) and says so.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from hframe_id.fitting.fit_run import FitRun, Fitted
from hframe_id.fitting.known_points import simulation_criterion
from hframe_id.fitting.noise_rounds import warm_solve
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import SolverState, StageReport

STAGE = "from rest, as validate replays"


def replays_rest(run: FitRun) -> bool:
    """Whether the fit needs the last solve: an output-error fit (continuity "exact") with a
    record at rest whose belt-free position the stages estimated (``rest_start`` "rigid")."""
    return (
        run.options.rest_start == "rigid"
        and run.options.continuity == "exact"
        and any(experiment.at_rest for experiment in run.problem.experiments)
    )


def solve_from_replayed_rest(
    run: FitRun,
    best: Fitted,
    recordings,
    estimated: bool = False,
    sensor_std: np.ndarray | None = None,
) -> tuple[FitRun, Fitted]:
    """The run and its end after the last solve (module docstring) on ``recordings``, from
    ``best``, the stages' converged end; or ``run`` and ``best`` with a stage saying the
    solve was rejected. At ``estimated`` levels it ends as a noise round does, and with the
    sensors' std ``sensor_std`` [SI] (rounds follow it) also once re-weighting gains more
    (``noise_rounds.warm_solve``)."""
    options = replace(run.options, rest_start="replay")
    ms = MultipleShooting(run.problem, transcription=options.transcription_options)
    replayed = replace(run, options=options, ms=ms)
    fresh, _ = ms.initial_nodes(run.problem.parameters(best.state.theta))
    nodes = best.state.nodes.copy()
    first = ms.first_window[[experiment.at_rest for experiment in run.problem.experiments]]
    nodes[first] = fresh[first]
    start = SolverState(nodes, best.state.theta.copy(), best.state.active.copy())
    state, gn = warm_solve(replayed, start, STAGE, estimated, sensor_std)
    ended = Fitted(state, gn, None, best.held)
    stalled = run.stages[-1]
    if not stalled.converged:
        judge = _replay_criterion(run.problem, recordings)
        last, stages = judge(state.theta), judge(best.state.theta)
        if not last < stages:
            run.stages.append(
                _verdict(
                    f"{STAGE}: rejected",
                    stalled,
                    best,
                    run.ms,
                    f"the solve from the replay's rest state did not converge ({stalled.message}) "
                    f"and replays no better than the stages' end (chi^2 / 2 from rest "
                    f"{last:.6g} against {stages:.6g}); the fit keeps the belt-free positions "
                    "it estimated",
                )
            )
            return run, best
        run.stages.append(
            _verdict(
                f"{STAGE}: kept unconverged",
                stalled,
                ended,
                ms,
                f"the solve from the replay's rest state stopped unconverged ({stalled.message}), "
                f"its end kept: replayed from rest it fits better than the stages' end "
                f"(chi^2 / 2 {last:.6g} against {stages:.6g})",
            )
        )
    return replayed, Fitted(state, gn, replayed.statistics(gn, state), best.held)


def _replay_criterion(problem, recordings):
    """theta -> chi^2 / 2 of ``recordings`` simulated from rest at ``problem``'s parameters
    ``theta``, under the problem's weights (each recording's) and latencies (``validate``'s
    replay)."""
    std = [dict(zip(problem.output_names, row, strict=True)) for row in problem.recording_std]
    latency = dict(problem.problem_options.latency_samples)

    def criterion(theta: np.ndarray) -> float:
        return simulation_criterion(problem.parameter_set(theta), recordings, std, latency)

    return criterion


def _verdict(name: str, stalled: StageReport, kept: Fitted, ms, message: str) -> StageReport:
    """The stage that records what became of a last solve that stopped unconverged
    (``stalled``): ``kept``, the end the fit keeps, on its transcription ``ms``."""
    evaluation, nodes = kept.state.evaluation, kept.state.nodes
    defect = float(np.max(np.abs(ms.defects(evaluation, nodes)), initial=0))
    return StageReport.verdict(name, stalled, message, evaluation.cost, defect)
