"""What the stages of one fit in one box share: the strategy's state, as one object.

``local_fit.fit_in_box`` makes a :class:`FitRun` once (problem, options, transcription, the
start from the measurements, the equation-error estimate) and hands it to each stage: the
output-error stages (``output_error.solve``), the identifiability holds
(``holds.hold_unidentified``), the restarts along unmeasured springs
(``unmeasured.restarts_along_unmeasured_springs``). A stage appends its reports to
``run.stages`` and counts its model evaluations in ``run.counter``; what it returns is a
:class:`Fitted` (or the solver state it reached). A new stage is one more such function.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from hframe_id.fitting.estimates import fit_result
from hframe_id.fitting.options import FitOptions, FitProgress
from hframe_id.fitting.problem import FitProblem
from hframe_id.fitting.progress import labelled
from hframe_id.fitting.result import FitResult
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import GaussNewton, SolverState, StageReport
from hframe_id.fitting.stages import estimate_states
from hframe_id.fitting.statistics import Statistics, compute_statistics
from hframe_id.fitting.stiffness_wall import at_the_wall


@dataclass
class FitRun:
    """One fit in one box, as its stages share it.

    ``problem`` and ``options`` (``FitOptions``, for the problem's model) of the fit;
    ``ms`` its transcription (``MultipleShooting``); ``nodes`` the node states from the
    measurements [SI: m, rad, m/s, rad/s] and ``velocity`` the velocity estimate at every
    sample [m/s, rad/s] (``MultipleShooting.initial_nodes``), where every solve starts;
    ``regression`` the equation-error estimate (log-parameters theta, seconds [s] it took)
    or None; ``progress`` the sink of the iterations (``progress.progress_sink``) or None;
    ``started`` the ``time.perf_counter()`` [s] the fit began at; ``stages`` the reports
    of the stages run so far; ``counter`` the model evaluations so far, under
    ``"evaluations"`` (one dict shared by every trial of the run and the noise rounds).
    """

    problem: FitProblem
    options: FitOptions
    ms: MultipleShooting
    nodes: np.ndarray
    velocity: np.ndarray
    regression: tuple[np.ndarray, float] | None
    progress: Callable[[FitProgress], None] | None
    started: float
    stages: list[StageReport] = field(default_factory=list)
    counter: dict[str, int] = field(default_factory=lambda: {"evaluations": 0})

    def add_evaluations(self, evaluations: int) -> None:
        """Count ``evaluations`` more model evaluations (a stage's solver's, or probes)."""
        self.counter["evaluations"] += evaluations

    def solver(self, ms: MultipleShooting, freeze_sloppy: bool = False) -> GaussNewton:
        """A Gauss-Newton iteration on ``ms`` (this run's transcription or a part of it)
        with the options' tuning (``FitOptions.gauss_newton``), reporting to ``progress``;
        ``freeze_sloppy``: parameters the data do not determine are held still."""
        return GaussNewton(ms, self.progress, freeze_sloppy, self.options.gauss_newton)

    def estimate_states(
        self,
        ms: MultipleShooting,
        nodes: np.ndarray,
        theta: np.ndarray,
        active: np.ndarray,
        stages: list[StageReport],
    ) -> tuple[np.ndarray, float]:
        """``stages.estimate_states`` on ``ms`` at the log-parameters ``theta`` held, by an
        iteration with this run's settings, its evaluations counted; its stage reported to
        ``stages``. Returns (the nodes, their penalty merit)."""
        solver = self.solver(ms)
        estimated = estimate_states(
            solver, nodes, self.velocity, theta, active, stages, self.options.strategy
        )
        self.add_evaluations(solver.evaluations)
        return estimated

    def statistics(self, solver: GaussNewton, state: SolverState) -> Statistics:
        """The statistics at ``state`` by the ``FitOptions.uncertainty`` method, from the
        condensed Jacobian of ``solver``'s transcription."""
        jac, residual, blocks = solver.condensed_jacobian(
            state.evaluation, state.nodes, state.active
        )
        names = tuple(n for n, a in zip(self.problem.free_names, state.active, strict=True) if a)
        return compute_statistics(
            jac, residual, blocks, solver.ms.n_nuisance, names, self.options.uncertainty
        )

    def against_the_wall(self, theta: np.ndarray) -> tuple[str, ...]:
        """The free parameters that put the log-parameters ``theta`` against the stiffness
        wall (``stiffness_wall.at_the_wall``; empty: not against it)."""
        p = self.problem.parameters(theta)
        return at_the_wall(self.problem, p, self.options, self.ms.dt)

    def trial(self, label: str) -> FitRun:
        """The run for a trial solve whose stages are judged before they join the fit's: its
        own (empty) stage list, progress lines prefixed by ``label``, the same counter."""
        return replace(self, stages=[], progress=labelled(self.progress, label))

    def result(self, fitted: Fitted) -> FitResult:
        """The ``FitResult`` of the run ending at ``fitted`` (``estimates.fit_result``)."""
        return fit_result(
            self.problem,
            self.options,
            self.ms,
            fitted.solver,
            fitted.state,
            self.stages,
            fitted.statistics,
            fitted.held,
            self.started,
            self.regression,
        )


@dataclass(frozen=True)
class Fitted:
    """Where a sequence of stages ended: the solver ``state`` (nodes, log-parameters, which
    are active), the ``solver`` of its last stage, the ``statistics`` there and the
    parameters ``held`` for identifiability (name -> relative std, its Gauss-Newton
    estimate, collinearity; ``holds.hold_unidentified``)."""

    state: SolverState
    solver: GaussNewton
    statistics: Statistics
    held: dict[str, tuple[float, float, float]] = field(default_factory=dict)
