"""Coordinates no output measures (one-axis: the idler pulley), and the restarts along the
belt stiffnesses that hold them.

The unmeasured idler's mode (set by k2 + k3 against J_2) makes the output error multimodal
along those stiffnesses, as a sinusoid's frequency is; a fit that ends in the wrong mode is
restarted with one stiffness moved at a time. docs/fitting.md, "One-axis", has the cost
profile and what the restarts change.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import casadi as ca
import numpy as np

from hframe_id.fitting.fit_run import FitRun, Fitted
from hframe_id.fitting.output_error import solve
from hframe_id.fitting.problem import FitProblem
from hframe_id.fitting.resolution import likelihood_gain
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import AT_BOUND


def measured_coordinates(ms: MultipleShooting) -> np.ndarray:
    """(n_q,) True for the coordinates an output measures, by their position or their rate
    (a tachometer)."""
    seen = np.any(ms.c[:, : ms.nq] != 0, axis=0)
    states = ms.output_states[ms.output_states >= 0]
    seen[states % ms.nq] = True
    return seen


def unmeasured_coordinates(ms: MultipleShooting) -> bool:
    """Whether some coordinate is measured by no output (one-axis: the idler pulley)."""
    return not bool(np.all(measured_coordinates(ms)))


def springs_at_unmeasured_coordinates(problem: FitProblem, ms: MultipleShooting) -> list[int]:
    """Free parameters (indices into ``problem.free``) that enter the generalised force on
    a coordinate no output measures through the potential energy (one-axis: k2, k3)."""
    model = problem.model
    x = ca.SX.sym("x", model.n_states)
    p = ca.SX.sym("p", len(model.parameters))
    _, potential = model.energy(x, p)
    unmeasured = np.flatnonzero(~measured_coordinates(ms))
    force = ca.gradient(potential, x)[unmeasured.tolist()]
    coupled = {j for j in range(p.shape[0]) if ca.depends_on(force, p[j])}
    return [f for f, i in enumerate(problem.free) if i in coupled]


def restarts_along_unmeasured_springs(run: FitRun, best: Fitted) -> Fitted:
    """Restarts from ``best`` with each free stiffness of a belt section at an unmeasured pulley
    moved by x/÷ each of ``StrategySettings.restart_factors``; keeps the lowest converged cost
    where it is a better fit by more than ``restart_min_gain`` (``likelihood_gain``),
    repeated while it improves (at most ``restart_limit`` solves), and reports them as one stage.
    A move is where the box leaves the stiffness (a move past a bound stops at it): one that
    leaves it where it is (the stiffness on that bound) is no restart, and one already solved
    from the current best is not solved again (its solve is deterministic).
    Also run when the fit has not converged: a converged restart replaces it.

    Each restart is one ``output_error.solve`` (with the state-estimation pre-pass) from the
    fit's end point with one stiffness moved, its stages judged apart (``FitRun.trial``).
    """
    problem, strategy = run.problem, run.options.strategy
    state, gn, stats = best.state, best.solver, best.statistics
    springs = springs_at_unmeasured_coordinates(problem, run.ms)
    start = time.perf_counter()
    tried = iterations = 0
    improved = True
    since_improved = set()  # (index, log-stiffness) solved from the current best: not again
    while improved and tried < strategy.restart_limit:
        improved = False
        for index in springs:
            for factor in (f**sign for f in strategy.restart_factors for sign in (1, -1)):
                moved = float(
                    np.clip(
                        state.theta[index] + math.log(factor),
                        problem.theta_lower[index],
                        problem.theta_upper[index],
                    )
                )
                if (
                    not state.active[index]
                    or tried >= strategy.restart_limit
                    or abs(moved - state.theta[index]) <= AT_BOUND
                    or (index, moved) in since_improved
                ):
                    continue
                since_improved.add((index, moved))
                theta = state.theta.copy()
                theta[index] = moved
                factor = math.exp(moved - state.theta[index])  # as the box left the move
                trial = run.trial(f"restart {tried + 1}, {problem.free_names[index]} x{factor:.3g}")
                trial_state, trial_gn = solve(trial, theta, state.active.copy(), prepass=True)
                tried += 1
                iterations += sum(st.iterations for st in trial.stages)
                gain = likelihood_gain(run.ms, state.evaluation.cost, trial_state.evaluation.cost)
                if trial.stages[-1].converged and gain > strategy.restart_min_gain:
                    state, gn, final = trial_state, trial_gn, trial.stages[-1]
                    improved = True
                    since_improved = set()
    if state is best.state:
        final = run.stages[-1]
    else:
        stats = run.statistics(gn, state)
    run.stages.append(
        replace(
            final,
            name=f"restarts along {', '.join(problem.free_names[i] for i in springs)}",
            iterations=iterations,
            wall_time_s=time.perf_counter() - start,
            message=f"{final.message}; {tried} restarts "
            f"(x/÷{', '.join(f'{f:g}' for f in strategy.restart_factors)}), "
            f"best cost {state.evaluation.cost:.6g}",
        )
    )
    return Fitted(state, gn, stats, best.held)
