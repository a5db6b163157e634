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
reproduces from the written file (issue 25, item 1). A solve that does not converge is
rejected, as a stalled noise round is: the fit keeps the stages' end and says so.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from hframe_id.fitting.fit_run import FitRun, Fitted
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


def solve_from_replayed_rest(run: FitRun, best: Fitted) -> tuple[FitRun, Fitted]:
    """The run and its end after the last solve (module docstring), from ``best``, the
    stages' converged end; or ``run`` and ``best`` with a stage saying the solve was
    rejected."""
    options = replace(run.options, rest_start="replay")
    ms = MultipleShooting(run.problem, transcription=options.transcription_options)
    fresh, _ = ms.initial_nodes(run.problem.parameters(best.state.theta))
    nodes = best.state.nodes.copy()
    first = ms.first_window[[experiment.at_rest for experiment in run.problem.experiments]]
    nodes[first] = fresh[first]
    start = SolverState(nodes, best.state.theta.copy(), best.state.active.copy())
    state, gn = warm_solve(ms, start, run.stages, run.counter, run.progress, STAGE, options)
    if run.stages[-1].converged:
        replayed = replace(run, options=options, ms=ms)
        return replayed, Fitted(state, gn, replayed.statistics(gn, state), best.held)
    stalled = run.stages[-1]
    run.stages.append(
        StageReport(
            name=f"{STAGE}: rejected",
            smoothing=stalled.smoothing,
            iterations=0,
            converged=True,
            message=f"the solve from the replay's rest state did not converge "
            f"({stalled.message}); the fit keeps the belt-free positions it estimated",
            cost=best.state.evaluation.cost,
            max_defect=float(
                np.max(np.abs(run.ms.defects(best.state.evaluation, best.state.nodes)), initial=0)
            ),
            wall_time_s=0.0,
        )
    )
    return run, best
