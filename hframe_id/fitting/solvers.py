"""The solvers of a fit's all-window stage, by name: where a new solver plugs in.

A solver is any object with a method ``solve(stage: Stage) -> StageReport``: it starts from
``stage.state`` (nodes, free log-parameters, which of them are active), solves the stage's
transcription to the options' tolerances, and leaves its end point in ``stage.state``
(``Stage.finish`` evaluates it and writes the report). Registered under a name, it is chosen
by ``FitOptions(solver=name)``; the start stages (equation error, moving windows) stay the
condensed Gauss-Newton's, and the statistics read the transcription's single-shooting
Jacobian at the end, whichever solver ran.

    from hframe_id.fitting.solvers import register_solver
    register_solver("my-solver", MySolver())
    fit_recordings(recordings, table, FitOptions(solver="my-solver"))

Built in: ``"gauss-newton"`` (the condensed Gauss-Newton, ``fitting.solver``), ``"ipopt"``
and ``"sqpmethod"`` (CasADi ``nlpsol`` on the same transcription, ``fitting.nlp``). A
solver for an unconstrained least-squares problem (SciPy ``least_squares``) works on
``stage.single_shooting()`` (examples/scipy_solver.py). This module imports neither CasADi
nor NumPy: option checks and ``--help`` use its names.
"""

from __future__ import annotations

import importlib
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from hframe_id.errors import OptionError, shown

if TYPE_CHECKING:
    from hframe_id.fitting.link_options import SolverOptions
    from hframe_id.fitting.single_shooting import SingleShooting
    from hframe_id.fitting.solver import GaussNewton, SolverState, StageReport

#: Built-in solvers: name -> "module:attribute" of the solver object (imported on use).
BUILT_IN = {
    "gauss-newton": "hframe_id.fitting.builtin_solvers:GAUSS_NEWTON",
    "ipopt": "hframe_id.fitting.builtin_solvers:IPOPT",
    "sqpmethod": "hframe_id.fitting.builtin_solvers:SQPMETHOD",
}
_REGISTERED: dict[str, Any] = {}


class Solver(Protocol):
    """What a solver of the all-window stage provides.

    ``penalty_fallback``: whether, if it fails from the nodes it was given, the stage is
    repeated from the measured nodes after a continuity-as-penalty stage (a local method
    needs that from a poor start; IPOPT and SQP globalise by themselves)."""

    penalty_fallback: bool
    description: str

    def solve(self, stage: Stage) -> StageReport: ...


@dataclass
class Stage:
    """One all-window stage handed to a solver.

    ``gauss_newton``: the transcription (``.ms``, every window with the stiffest window's
    substeps) and its linearisation (``condensed_jacobian``); ``state``: the start, where
    the solver leaves its end; ``options``: the solver's (``FitOptions.solver_options``:
    ``max_iterations``, ``step_tol``, ``defect_tol``); ``settings``: the Gauss-Newton
    solver's own stage settings (trust-region radius, cost tolerance, watchdog,
    re-weighting), which other solvers ignore."""

    label: str
    gauss_newton: GaussNewton
    state: SolverState
    options: SolverOptions
    settings: dict[str, Any] = field(default_factory=dict)
    started: float = field(default_factory=time.perf_counter)

    @property
    def transcription(self):
        """The ``MultipleShooting`` transcription the stage solves."""
        return self.gauss_newton.ms

    @property
    def smoothing(self) -> tuple[float, float]:
        """Coulomb smoothing velocities of the stage ([m/s], [rad/s])."""
        return self.transcription.problem.smoothing

    def single_shooting(self) -> SingleShooting:
        """The stage as an unconstrained least-squares problem in the estimated initial
        states and the active log-parameters (``fitting.single_shooting``)."""
        from hframe_id.fitting.single_shooting import SingleShooting

        return SingleShooting(self.transcription, self.state)

    def finish(self, name: str, iterations: int, converged: bool, message: str):
        """Evaluate ``state`` where the solver left it and report the stage: converged only
        if the solver says so and every continuity defect is within ``defect_tol``."""
        import numpy as np

        from hframe_id.fitting.solver import StageReport

        ms, state = self.transcription, self.state
        state.evaluation = ms.evaluate(state.nodes, state.theta, self.smoothing)
        state.velocity_hint = state.evaluation.states[:, :, ms.nq :]
        defect = float(np.max(np.abs(ms.defects(state.evaluation, state.nodes)), initial=0))
        converged = converged and defect <= self.options.defect_tol
        return StageReport(
            name=f"{self.label} ({name})",
            smoothing=self.smoothing,
            iterations=iterations,
            converged=converged,
            message=f"converged: {message}" if converged else message,
            cost=state.evaluation.cost,
            max_defect=defect,
            wall_time_s=time.perf_counter() - self.started,
            substeps=state.evaluation.n_substeps,
        )


def register_solver(name: str, solver: Solver) -> None:
    """Make ``solver`` available as ``FitOptions(solver=name)``; a built-in name is refused."""
    if name in BUILT_IN:
        raise OptionError(f"solver {name!r} is built in; register yours under another name")
    if not callable(getattr(solver, "solve", None)):
        raise OptionError(f"solver {name!r}: {type(solver).__name__} has no solve(stage) method")
    _REGISTERED[name] = solver


def solver_names() -> tuple[str, ...]:
    """Every solver name ``FitOptions.solver`` accepts: the built-in ones, then registered."""
    return (*BUILT_IN, *_REGISTERED)


def check_solver_name(name: object) -> None:
    """Raise OptionError unless ``name`` is one of ``solver_names()`` (``SolverOptions``
    checks its solver with it; a solver may be unregistered after that, so ``solver_named``
    checks again)."""
    if name not in solver_names():
        raise OptionError(f"solver must be one of {', '.join(solver_names())}, got {shown(name)}")


def solver_named(name: str) -> Solver:
    """The solver registered as ``name``."""
    check_solver_name(name)
    if name in _REGISTERED:
        return _REGISTERED[name]
    module, attribute = BUILT_IN[name].split(":")
    return getattr(importlib.import_module(module), attribute)
