"""The point a fit begins from: the best it knows, by the criterion its answer is judged by.

A local optimizer started from the user's table answers for that table: on the heavy plant
of issue 25 five starts (Table 4.2 x log-uniform [1/2, 2]) ended at five optima
(docs/studies/2026-11-26-heavy-plant-optima.md). The end of a fit is judged against the points
it knows (``known_points``: the start, the equation-error estimate, the model's reference
files, the user's ``FitOptions.known_points``); here the same points are judged before the
fit, and the fit begins from the best of them. Where one of them wins, every start that it
beats begins from it, so their answers are one answer.

The judge is the written file's criterion without the fit's noise levels, which do not exist
yet: each training record simulated from rest (``validation.replay.simulate_channels``, what
``validate`` replays), concentrated over the noise levels, floored at the sensors' std
(``known_points.simulation_criterion`` with ``concentrated``; chi^2 / 2 plus a constant
while every channel fits within its sensor's noise, so matched data are ranked as under the
sensors' weights). A point replaces the start only when it is better by more than
``open_ended.LIKELIHOOD_RATIO_95`` (significant at 95 %): the user's start wins ties. The
equation-error estimate is judged here with the others, so the fit's first stage then takes
the screen's point as it is (``local_fit.fit_in_box`` with ``screened``).

The screen needs every record to start at rest: a record in motion has no initial state
before the fit estimates one, and judged from rest every point would be judged on the wrong
start. Such fits (EMPS: records in motion), prediction-error fits, fits with priors (centred
on the start: ``FitOptions.consider_method`` "prior") and fits asked to begin as given
(``FitOptions.screen_start`` off) begin from the user's start. A fit that began elsewhere
reports that point as its start (``FitResult.initial``: a parameter held for
identifiability is held there), and its message says where it began and why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from hframe_id.fitting.equation_error import equation_error_start
from hframe_id.fitting.known_points import Criterion, Simulations, reference_points
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.problem import FitProblem, build_problem
from hframe_id.fitting.resolution import LIKELIHOOD_RATIO_95
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.parameters import ParameterSet

EQUATION_ERROR = "the equation-error estimate"


@dataclass(frozen=True)
class Beginning:
    """Where a fit in the default box begins (``fit._fit_widening``): ``parameters`` and
    their ``criterion`` (the screen's judge, module docstring; None until judged);
    ``statement``, for the fit's message, says why it is not the start ("" for the start)."""

    parameters: ParameterSet
    criterion: float | None = None
    statement: str = ""

    def or_better(self, end: ParameterSet, judge: Criterion) -> Beginning:
        """This beginning, or ``end`` (where a fit ended on its box) if ``judge`` finds it
        better by more than ``LIKELIHOOD_RATIO_95``: the widened fit begins from the best
        point it knows, as the first one did."""
        own = judge(self.parameters) if self.criterion is None else self.criterion
        criterion = judge(end)
        if not criterion < own - LIKELIHOOD_RATIO_95:
            return replace(self, criterion=own)
        return Beginning(
            end,
            criterion,
            "the box widened, the fit continued from where it had ended on it (concentrated "
            f"criterion from rest {criterion:.6g} against {own:.6g} where it began)",
        )


@dataclass(frozen=True)
class ScreenedStart:
    """Where a fit began: ``label`` and ``parameters`` of the point (``"the start"`` for the
    user's); ``criteria``, the screen's criterion of every point judged, by label (the
    start's first; dimensionless, concentrated chi^2 / 2 units; inf where the simulation
    failed); ``candidates``, the (label, parameter set) judged, sets equal in their free
    values once; ``criterion``, the judge (``known_points.Criterion``, concentrated, from
    rest). All empty (None) when the
    screen did not run, ``skipped`` saying why."""

    label: str
    parameters: ParameterSet
    criteria: dict[str, float]
    candidates: tuple[tuple[str, ParameterSet], ...] = ()
    skipped: str = ""
    criterion: Criterion | None = None

    @property
    def moved(self) -> bool:
        """Whether the fit began elsewhere than at the user's start."""
        return self.label != "the start"

    def statement(self) -> str:
        """One line for the fit's message: where it began and why."""
        return (
            f"began from {self.label}, whose simulation from rest fits the records better than "
            f"the given start's (concentrated criterion {self.criteria[self.label]:.6g} "
            f"against {self.criteria['the start']:.6g})"
        )


def screen_start(
    recordings, initial: ParameterSet, options: FitOptions, simulations: Simulations | None = None
) -> ScreenedStart:
    """The best of the user's start ``initial``, the equation-error estimate (with
    ``options.first_stage``), the model's reference files and ``options.known_points``, each
    with ``initial``'s fixed parameters and its free values clipped into the user's bounds,
    by the module's criterion on ``recordings``; ``initial`` unless another is better by more
    than ``LIKELIHOOD_RATIO_95``, or where the screen does not run (module docstring); the
    runs kept in ``simulations`` (the fit's, or None)."""
    skipped = ""
    if not options.screen_start:
        skipped = "off"
    elif options.continuity != "exact":
        skipped = "a prediction-error fit"
    if skipped:
        return ScreenedStart("the start", initial, {}, skipped=skipped)
    problem = build_problem(recordings, initial, options)
    if not all(experiment.at_rest for experiment in problem.experiments):
        return ScreenedStart("the start", initial, {}, skipped="a record starts in motion")
    if np.any(problem.prior_weight > 0):
        # A prior is centred on the start (``FitProblem.prior_weight``): the user's values.
        return ScreenedStart("the start", initial, {}, skipped="priors centred on the start")
    # In SI, not through theta = ln(p / p_start) where avoidable: the round trip moves the
    # last bits with the start, and the fit's path amplifies them (two seeded starts of the
    # heavy plant began from Table 4.1 so and ended 15 % apart in motor-angle rms).
    regressed = equation_error_theta(problem, options) if options.first_stage else None
    candidates = known_candidates(initial, problem, options, regressed)
    judge = Criterion(
        tuple(recordings),
        dict(zip(problem.output_names, problem.channel_std, strict=True)),
        dict(problem.problem_options.latency_samples),
        concentrated=True,
        simulations=simulations,
    )
    criteria = {label: judge(params) for label, params in candidates}
    label = min(criteria, key=criteria.get)
    if not criteria[label] < criteria["the start"] - LIKELIHOOD_RATIO_95:
        return ScreenedStart("the start", initial, criteria, candidates, criterion=judge)
    return ScreenedStart(label, dict(candidates)[label], criteria, candidates, criterion=judge)


def known_candidates(
    initial: ParameterSet, problem: FitProblem, options: FitOptions, regressed=None
) -> tuple[tuple[str, ParameterSet], ...]:
    """(label, parameter set) of every point a fit of ``problem`` knows: the start
    ``initial``, the equation-error estimate (``regressed``, log-parameters theta of
    ``problem``, if given), the model's reference files and ``options.known_points``
    (``known_points.reference_points``); each with ``initial``'s fixed parameters and its
    free values clipped into the user's bounds (not the default box, drawn around the start),
    sets equal in their free values once, the first label kept."""
    points = [("the start", initial)]
    if regressed is not None:
        points.append((EQUATION_ERROR, problem.parameter_set(regressed)))
    points += reference_points(initial.variant, options.known_points)
    unique = {}
    for label, point in points:
        clipped = _within_user_bounds(initial, point, problem.free_names, options.bounds)
        unique.setdefault(tuple(clipped.values[n] for n in problem.free_names), (label, clipped))
    return tuple(unique.values())


def equation_error_theta(problem: FitProblem, options: FitOptions) -> np.ndarray:
    """The equation-error estimate (``equation_error.equation_error_start``) of ``problem``
    as its log-parameters theta, from the measured positions of ``options``' transcription."""
    ms = MultipleShooting(problem, transcription=options.transcription_options)
    ms.initial_nodes(problem.p_initial)  # the measured positions the regression needs
    return equation_error_start(
        problem, ms.measured_positions, ms.measured_usable, threads=ms.threads
    )


def _within_user_bounds(initial: ParameterSet, point: ParameterSet, free, bounds) -> ParameterSet:
    """``initial`` with the ``free`` parameters' values of ``point``, each clipped into the
    user's ``bounds`` [SI] where it has one."""
    values = {}
    for name in free:
        low, high = bounds.get(name, (-math.inf, math.inf))
        values[name] = min(max(float(point.values[name]), low), high)
    return initial.replace_values(**values)
