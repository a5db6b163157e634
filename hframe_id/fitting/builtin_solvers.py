"""The built-in solvers of the all-window stage (``fitting.solvers`` names them)."""

from __future__ import annotations

from dataclasses import dataclass

from hframe_id.fitting.nlp import NlpSettings, solve_nlp
from hframe_id.fitting.solver import StageReport
from hframe_id.fitting.solvers import Stage


@dataclass(frozen=True)
class GaussNewtonSolver:
    """The condensed Gauss-Newton iteration of ``fitting.solver`` (its stage settings:
    ``Stage.settings``)."""

    penalty_fallback: bool = True
    description: str = "Gauss-Newton on the lifted problem (CasADi)"

    def solve(self, stage: Stage) -> StageReport:
        """Iterate from ``stage.state`` to the options' tolerances."""
        options = stage.options
        return stage.gauss_newton.run(
            stage.state,
            stage.label,
            stage.smoothing,
            options.max_iterations,
            options.step_tol,
            options.defect_tol,
            **stage.settings,
        )


@dataclass(frozen=True)
class NlpSolver:
    """A CasADi ``nlpsol`` solver on the same transcription, as one NLP (``fitting.nlp``);
    it globalises by itself (no penalty fallback)."""

    name: str
    label: str
    penalty_fallback: bool = False

    @property
    def description(self) -> str:
        """The method, as the parameter file's provenance states it."""
        return f"{self.label} (CasADi nlpsol, Gauss-Newton Hessian)"

    def solve(self, stage: Stage) -> StageReport:
        """Solve the stage's NLP from ``stage.state`` within the options' iterations. Where
        ``sqpmethod`` stops on a search direction below its ``min_step_size`` (its absolute
        dual tolerance out of reach, or a QP it could not solve: ``NlpOutcome.small_step``),
        the stage is converged if the Gauss-Newton step from that point moves no parameter
        by more than ``step_tol``: the default solver's own criterion."""
        state = stage.state
        outcome = solve_nlp(
            stage.transcription,
            state.nodes,
            state.theta,
            state.active,
            stage.smoothing,
            NlpSettings(solver=self.name, max_iter=stage.options.max_iterations),
        )
        state.nodes, state.theta = outcome.nodes, outcome.theta
        converged, message = outcome.converged, outcome.message
        if outcome.small_step:
            step = stage.gauss_newton.step_from(state, stage.smoothing)
            step_tol = stage.options.step_tol
            converged = step <= step_tol
            message = (
                f"search direction below its minimum; the Gauss-Newton step from there "
                f"{step:.1e} {'<=' if converged else '>'} {step_tol:.0e}"
            )
        return stage.finish(self.label, outcome.iterations, converged, message)


GAUSS_NEWTON = GaussNewtonSolver()
IPOPT = NlpSolver("ipopt", "IPOPT")
SQPMETHOD = NlpSolver("sqpmethod", "SQP")
