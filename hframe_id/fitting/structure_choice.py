"""A model that nests in a larger one: fit the larger one too, keep the one the data choose.

hframe-8 is hframe-8-current-limit with I_max -> infinity (``ModelDeclaration.nests_in``).
Fitted to a rig whose amplifiers limit their current below what its steps ask, hframe-8 bends
its other parameters around the missing limit: it follows the training records better than
the plant's own reduction and predicts held-out records 1.5-2.6 x worse; the limited model
with I_max free predicts them 0.04-0.15 x the reduction's (issue 25; dev plants 48, 1 and test
plant 1188 in docs/studies/2026-11-28-fitting-the-current-limit.md). Where the rig has no
limit, the larger model puts one where it helps the training records, and predicts worse.
So the data choose, where the smaller model's fit found model error (it estimated noise
levels: ``noise_rounds``; a model that follows the records to its sensors' noise lacks nothing
the data can show), in three steps:

1. **Start.** The extra parameter is profiled at the user's start: the best, by the start
   screen's criterion (``start_screen``: concentrated, from rest), of the larger model's
   reference value times 2^(k/4), k = -4..4 (within the seeded starts' x/÷2,
   ``multistart.SPREAD``). If none of them beats the smaller model itself there, the larger
   fit from there is the smaller one's (a limit that does not bind has no gradient). The
   same profile is taken at the other points the smaller fit's screen judged that were not
   fitted to the data (the model's reference files, the user's known points), and the
   larger fit starts from the best profiled point where the profile gains, the user's start
   winning unless another is better by the 95 % likelihood ratio (the screen's rule); where
   no profile gains, it is not run. (A seeded start of the shipped plant, Table 4.2 x
   log-uniform [1/2, 2], that the screen moved to Table 4.2 showed no gain at the start and
   kept hframe-8, 30 % above the four others' motor-angle rms. Profiled at the
   equation-error estimate, the smaller model fitted to the data and bent around the missing
   limit, test plant 1188's 7.5 A limit started at 11.3 A and ended undetermined at 12.2 A.)
2. **Fit.** The larger model, with the smaller fit's free set and the extra parameter free,
   its structure as given.
3. **Choice.** The larger model is kept when its fit succeeded, its written file simulates
   the records better than the smaller one's by more than the 95 % likelihood ratio on the
   smaller fit's criterion (``known_points.Criterion``, as validate replays each file) once
   that gain is scaled for correlated residuals, and the extra parameter is identified
   (relative std within ``FitOptions.identifiability_threshold``): a parameter the data do
   not pin is a stand-in for some other mismatch, not a limit. Otherwise the smaller
   model's fit stands. The criterion's gain is a likelihood ratio for independent errors;
   under model error the residuals are correlated over many samples and its spread is
   larger by the extra parameter's robust over textbook variance (its sampling variance over
   what independent errors would give, ``fitting.statistics``), so the gain is divided by
   that ratio (``evidence_scale``, a Satorra-Bentler scaling of the likelihood-ratio test).
   Test plant 1294 (a linear plant: no limit) kept an 8.6 A limit for a gain of 3.6 (robust
   std 4 x the textbook one: 0.23 scaled) and predicted held-out records 7.1 x worse than
   its reduction; on the seven realistic records the limit gains 10,268 (scaled 83) and on
   dev plant 48 18,192 (scaled 126).
4. **Continuation.** Where the larger fit simulates the records better but is not kept (its
   extra parameter not identified, a limit that hardly binds, or its gain within what
   correlated residuals give), its end is, but for that parameter, a point
   of the smaller model that the smaller fit did not reach: the smaller model is fitted again
   from there, and kept if it simulates the records better than the first smaller fit by more
   than the likelihood ratio (a fit never ends worse than a point it knows, ``known_points``).
   Dev plant 26 of issue 25: hframe-8 ended at -92,364, the limited fit at -142,609 with I_max
   undetermined (std 1.5e23 relative), and the hframe-8 fit predicted held-out records 3.4 x
   worse than the plant's own reduction.

Between steps 2 and 3, a larger fit that ends worse than the smaller fit by more than the
likelihood ratio has not converged: the smaller fit's end is a point of the larger model (the
extra parameter where it does not bind), and a fit is never worse than a point it knows. The
larger model is then fitted again from the smaller fit's end, the extra parameter at the
larger model's reference value, and the better of its two fits goes on to step 3. A larger
fit that ends with the extra parameter undetermined, from a start above the profile's lowest
value, may have started where the limit hardly binds, where it has no gradient to move: it is
fitted again from the same start with the extra parameter at that lowest value (a limit that
binds can rise until it no longer does), and again the better fit goes on. On a 4 s
designed record of a damped plant with a 7.7 A limit (issue 29's check, dev seed 1):
hframe-8 -111,976, the limited fit from Table 4.2 -103,615, from the hframe-8 fit's end
-128,354 with I_max 7.05 A (the plant's six steps: 7.03 A). On test plant 1195 and dev seed
5's design record (no limit), where the first limited fit also ended worse, hframe-8 is still
kept (docs/studies/2026-11-29-design-check-at-head-and-the-fleet-scatters-critical-value.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from hframe_id.errors import FitError
from hframe_id.fitting.known_points import Criterion, replayed_starts
from hframe_id.fitting.multistart import SPREAD
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.problem import DEFAULT_FREE
from hframe_id.fitting.progress import labelled, progress_sink
from hframe_id.fitting.resolution import LIKELIHOOD_RATIO_95
from hframe_id.fitting.start_screen import EQUATION_ERROR, ScreenedStart
from hframe_id.models import build_model, declaration, variants
from hframe_id.parameters import ParameterSet, load_parameter_file

if TYPE_CHECKING:  # the result holds a StructureChoice
    from hframe_id.fitting.result import FitResult

#: Start candidates of the extra parameter per octave of ``SPREAD``: quarter-octave steps.
STEPS_PER_OCTAVE = 4


@dataclass(frozen=True)
class StructureChoice:
    """Which of two nested models a fit kept, and why.

    Attributes
    ----------
    asked, larger : the model of the fit's start, and the model it nests in.
    extra, unit : the larger model's additional parameter and its unit.
    start : the larger fit's start (None: not run, the smaller model followed the records to
        the sensors' noise, or no start value improved on it at the start).
    criteria : the criterion of each fitted model's written file, by variant, on the smaller
        fit's scale (``known_points.Criterion``; lower is better).
    extra_value, extra_relative_std : the larger fit's estimate [unit] and its relative std.
    larger_success : whether the larger fit succeeded.
    chosen : the variant kept.
    failure : why the larger fit gave no result (it raised), else "".
    continued : the criterion of the smaller model fitted again from the larger fit's end
        (step 4 of the module's doc), where that fit was kept; else NaN.
    first_larger : the criterion of the larger fit from step 1's start where a second larger
        fit ran and did better (the module's doc); ``start`` is then that second fit's start.
        Else NaN.
    second_larger : the criterion of that second larger fit where it ran and did not do
        better than the first (infinite where it raised); else NaN.
    second_from, second_why : where the second larger fit started, and why it ran (what the
        first did); "" where it did not run.
    evidence_scale : the larger fit's extra parameter's textbook over robust variance, at
        most 1: what its criterion gain counts for (step 3); 1 where not fitted.
    """

    asked: str
    larger: str
    extra: str
    unit: str
    start: ParameterSet | None
    criteria: dict[str, float]
    extra_value: float = math.nan
    extra_relative_std: float = math.nan
    larger_success: bool = False
    chosen: str = ""
    failure: str = ""
    continued: float = math.nan
    first_larger: float = math.nan
    second_larger: float = math.nan
    second_from: str = ""
    second_why: str = ""
    evidence_scale: float = 1.0

    @property
    def scaled_gain(self) -> float:
        """The larger model's criterion gain over the smaller one's, times ``evidence_scale``
        (NaN where the larger model was not fitted)."""
        gain = self.criteria.get(self.asked, math.nan) - self.criteria.get(self.larger, math.nan)
        return gain * self.evidence_scale

    @property
    def tried(self) -> bool:
        """Whether the larger model was fitted."""
        return self.start is not None

    def statement(self) -> str:
        """One sentence: what was tried, what was kept, and the numbers that decided."""
        if not self.tried and not self.criteria:
            return (
                f"{self.larger} not tried: {self.asked} follows the records to the sensors' noise"
            )
        if not self.tried:
            return (
                f"{self.larger} not tried: no {self.extra} within x/÷2 of its reference "
                f"improved on {self.asked} at the start or the model's reference files"
            )
        if self.failure:
            return f"{self.asked} kept: the {self.larger} fit {self.failure}"
        larger = self.criteria.get(self.larger, math.nan)
        numbers = (
            f"{self.extra} = {self.extra_value:.4g} {self.unit} (relative std "
            f"{self.extra_relative_std:.2g}), criterion {larger:.6g} against "
            f"{self.criteria[self.asked]:.6g} for {self.asked}"
        )
        if not math.isnan(self.first_larger):
            numbers += (
                f"; fitted from {self.second_from}, where the first {self.larger} fit "
                f"{self.second_why} ({self.first_larger:.6g})"
            )
        if not math.isnan(self.second_larger):
            outcome = (
                "which raised"
                if math.isinf(self.second_larger)
                else f"no better ({self.second_larger:.6g})"
            )
            numbers += f"; fitted again from {self.second_from}, {outcome}"
        if self.chosen == self.larger:
            return f"{self.larger} kept: {numbers}"
        if not math.isnan(self.continued):
            return (
                f"{self.asked} kept, fitted again from the {self.larger} fit's end without "
                f"{self.extra}: criterion {self.continued:.6g} against "
                f"{self.criteria[self.asked]:.6g} for the first {self.asked} fit ({numbers})"
            )
        if not self.larger_success:
            why = f"the {self.larger} fit failed"
        elif not self.scaled_gain > LIKELIHOOD_RATIO_95:
            why = f"{self.larger} not better by the 95 % likelihood ratio"
            if self.evidence_scale < 1:
                why += (
                    f" once scaled for correlated residuals (gain x{self.evidence_scale:.2g}: "
                    f"{self.scaled_gain:.3g})"
                )
        else:
            why = f"{self.extra} poorly determined: a stand-in for some other mismatch"
        return f"{self.asked} kept, {why} ({numbers})"


def check_nesting(variant: str, options: FitOptions) -> None:
    """Before any solving: ``FitError`` where ``variant`` nests in a model that cannot be fitted
    in its place (``_extra_parameter``) and the fit would choose."""
    larger = declaration(variant).nests_in
    if options.structure == "choose" and larger is not None:
        _extra_parameter(variant, larger)


def _extra_parameter(asked: str, larger: str) -> str:
    """The one parameter of ``larger`` that ``asked`` lacks; ``FitError`` naming what is wrong
    where ``larger`` is not a registered model with a reference file and one parameter more."""
    where = f"{declaration(asked).source}: nests_in {larger!r}"
    if larger not in variants():
        raise FitError(f"{where}: no such model (known: {', '.join(variants())})")
    if declaration(larger).reference_file is None:
        raise FitError(f"{where}: it declares no reference parameter file to start from")
    extra = [
        name
        for name in declaration(larger).parameter_names
        if name not in declaration(asked).parameter_names
    ]
    if len(extra) != 1:
        raise FitError(f"{where}: it must have exactly one parameter more, has {extra}")
    return extra[0]


def _in_larger(
    params: ParameterSet, reference: ParameterSet, extra: str, value: float
) -> ParameterSet:
    """``params`` as a parameter set of ``reference``'s (the larger) model, ``extra`` =
    ``value``, the larger model's other parameters at ``reference``'s values."""
    names = build_model(reference.variant).parameter_names
    kept = {k: v for k, v in params.values.items() if k in names}
    return replace(
        reference.replace_values(**kept, **{extra: value}),
        title=f"{params.title}, {extra} from its profile",
        source=params.source,
    )


def _larger_start(
    bases: list[ParameterSet], larger: str, extra: str, criterion: Criterion
) -> ParameterSet | None:
    """The larger model's start (step 1 of the module's doc), or None: ``bases`` are the
    points the extra parameter is profiled at, the user's start first, which wins unless
    another is better by more than ``LIKELIHOOD_RATIO_95`` (the start screen's rule)."""
    reference = load_parameter_file(declaration(larger).reference_file)
    profiled = []
    for base in bases:
        candidates = [
            _in_larger(base, reference, extra, value)
            for value in _profile_values(reference.values[extra])
        ]
        scores = [criterion(c) for c in candidates]
        best = min(range(len(candidates)), key=scores.__getitem__)
        # the limit must bind to some gain at its base, else the larger fit is the smaller's
        gains = scores[best] < criterion(base)
        profiled.append((scores[best], candidates[best]) if gains else (math.inf, None))
    (at_start, start), *others = profiled
    best_other, other = min(others, key=lambda scored: scored[0], default=(math.inf, None))
    return other if best_other < at_start - LIKELIHOOD_RATIO_95 else start


def _profile_values(reference_value: float) -> list[float]:
    """The extra parameter's values profiled at a start (step 1 of the module's doc):
    ``reference_value`` x 2^(k / ``STEPS_PER_OCTAVE``) within ``SPREAD``, ascending."""
    steps = round(STEPS_PER_OCTAVE * math.log2(SPREAD[1]))
    return [reference_value * 2.0 ** (k / STEPS_PER_OCTAVE) for k in range(-steps, steps + 1)]


def _profile_bases(initial: ParameterSet, screen: ScreenedStart | None) -> list[ParameterSet]:
    """Where the larger model's extra parameter is profiled (step 1 of the module's doc): the
    user's start, then every other point the smaller fit's start screen judged but the
    equation-error estimate (the smaller model fitted to the data, bent around what it
    lacks): the model's reference files and the user's known points."""
    if screen is None or not screen.candidates:
        return [initial]
    others = [p for label, p in screen.candidates if label not in ("the start", EQUATION_ERROR)]
    return [initial, *others]


def larger_options(options: FitOptions, extra: str) -> FitOptions:
    """The options of the larger model's fit: the same free set and the extra parameter, the
    structure as given, no known points (they are of the smaller model)."""
    free = (*(options.free or (DEFAULT_FREE,)), extra)
    progress = labelled(progress_sink(options), f"with {extra}")
    return replace(
        options, free=free, structure="as-given", known_points=(), progress=progress, verbose=0
    )


def with_structure_choice(
    recordings, initial: ParameterSet, options: FitOptions, result: FitResult, fit
) -> FitResult:
    """``result`` (the fit of ``initial``'s model), or the fit of the model it nests in where
    the data choose that one (module doc), with the choice in ``diagnostics.structure`` and
    its statement in the message. ``fit(recordings, initial, options)`` fits."""
    asked = initial.variant
    larger = declaration(asked).nests_in
    if options.structure != "choose" or larger is None or options.continuity != "exact":
        return result
    extra = _extra_parameter(asked, larger)
    unit = {s.name: s.unit for s in declaration(larger).parameters}[extra]
    noise = result.diagnostics.noise
    if noise is None or noise.method != "estimated":
        return _chosen(result, StructureChoice(asked, larger, extra, unit, None, {}, chosen=asked))
    criterion = Criterion.of(result, recordings)
    criteria = {asked: criterion(result.parameters, (replayed_starts(result),))}
    screen = result.diagnostics.start_screen
    judge = criterion if screen is None or screen.criterion is None else screen.criterion
    start = _larger_start(_profile_bases(initial, screen), larger, extra, judge)
    if start is None:
        choice = StructureChoice(asked, larger, extra, unit, None, criteria, chosen=asked)
        return _chosen(result, choice)
    try:
        other = fit(recordings, start, larger_options(options, extra))
    except Exception as err:  # the smaller fit is finished: it stands, nothing is lost
        failed = f"raised {type(err).__name__}: {err}"
        choice = StructureChoice(asked, larger, extra, unit, start, criteria, chosen=asked)
        return _chosen(result, replace(choice, failure=failed))
    criteria[larger] = criterion(other.parameters, (replayed_starts(other),))
    first_larger = second_larger = math.nan
    second_from, second_why, second_start = _second_start(
        result, start, other, criteria, extra, unit
    )
    if second_start is not None:
        again = _larger_fit(recordings, second_start, extra, options, fit, second_from)
        second = (
            math.inf if again is None else criterion(again.parameters, (replayed_starts(again),))
        )
        if second < criteria[larger]:
            first_larger = criteria[larger]
            start, other, criteria[larger] = second_start, again, second
        else:
            second_larger = second
    estimate = other.estimates[extra]
    choice = StructureChoice(
        asked,
        larger,
        extra,
        unit,
        start,
        criteria,
        extra_value=estimate.estimate,
        extra_relative_std=estimate.relative_std,
        larger_success=other.success,
        chosen=asked,
        first_larger=first_larger,
        second_larger=second_larger,
        second_from=second_from,
        second_why=second_why,
        evidence_scale=_evidence_scale(estimate),
    )
    keep = other.success and choice.scaled_gain > LIKELIHOOD_RATIO_95 and estimate.identified
    if keep:
        choice = replace(choice, chosen=larger)
    better = criteria[larger] < criteria[asked] - LIKELIHOOD_RATIO_95
    if keep or not (other.success and better):
        return _chosen(other if keep else result, choice)
    again, continued = _continued(recordings, initial, options, other, criterion, fit)
    if continued < criteria[asked] - LIKELIHOOD_RATIO_95:
        return _chosen(again, replace(choice, continued=continued))
    return _chosen(result, choice)


def _evidence_scale(estimate) -> float:
    """What a criterion gain from fitting ``estimate``'s parameter counts for (step 3 of the
    module's doc): its textbook over robust relative variance, at most 1 (1 where either is
    not a positive number)."""
    robust, textbook = estimate.relative_std, estimate.relative_std_gn
    if not (robust > 0 and textbook > 0 and math.isfinite(robust)):
        return 1.0
    return min(1.0, (textbook / robust) ** 2)


def _second_start(result, start: ParameterSet, other, criteria: dict, extra: str, unit: str):
    """(where, why, start) of a second fit of the larger model, or ("", "", None) where none
    runs (the module's doc, between steps 2 and 3). Where the first larger fit ``other`` ended
    worse than the smaller fit ``result`` by more than the likelihood ratio, it has not
    converged: from the smaller fit's end, the extra parameter at the larger model's
    reference value. Where it ended with the extra parameter undetermined from a start above
    the profile's lowest value: from ``start`` with the extra parameter at that lowest value.
    A current limit that hardly binds at its start has no gradient to move (test plant 1307
    of issue 25: a 6.2 A limit, the fit from 9.51 A ended at 9.59 A with relative std 3.5e16;
    from 4, 5.66 and 8 A it found 6.185 A), and one that binds can rise until it no longer
    does."""
    smaller, larger = result.variant, other.variant
    reference = load_parameter_file(declaration(larger).reference_file)
    if criteria[larger] > criteria[smaller] + LIKELIHOOD_RATIO_95:
        from_end = _in_larger(result.parameters, reference, extra, reference.values[extra])
        return f"the {smaller} fit's end", "ended worse", from_end
    lowest = _profile_values(reference.values[extra])[0]
    if not other.estimates[extra].identified and start.values[extra] > lowest:
        where = f"{extra} {lowest:.3g} {unit}, its profile's lowest"
        return where, f"ended with {extra} undetermined", start.replace_values(**{extra: lowest})
    return "", "", None


def _larger_fit(recordings, start: ParameterSet, extra: str, options: FitOptions, fit, where: str):
    """The larger model's second fit from ``start`` (labelled with ``where`` it starts), or
    None if it raised (the first larger fit and the smaller one are finished: they stand)."""
    progress = labelled(progress_sink(options), f"with {extra}, from {where}")
    try:
        return fit(recordings, start, replace(larger_options(options, extra), progress=progress))
    except Exception:
        return None


def _continued(recordings, initial: ParameterSet, options: FitOptions, other, criterion, fit):
    """The smaller model (``initial``'s) fitted again from the larger fit ``other``'s end,
    the extra parameter dropped (step 4 of the module's doc), reported from ``initial``, and
    its file's criterion (inf if that fit failed or raised: the first smaller fit stands)."""
    names = build_model(initial.variant).parameter_names
    start = initial.replace_values(**{n: other.parameters.values[n] for n in names})
    progress = labelled(progress_sink(options), f"from the {other.variant} fit's end")
    try:
        again = fit(recordings, start, replace(options, structure="as-given", progress=progress))
    except Exception:  # the first smaller fit is finished: it stands
        return None, math.inf
    if not again.success:
        return None, math.inf
    return again.started_from(initial), criterion(again.parameters, (replayed_starts(again),))


def _chosen(result: FitResult, choice: StructureChoice) -> FitResult:
    """``result`` with the choice in its diagnostics and its statement in the message."""
    result = result.with_diagnostics(structure=choice)
    return replace(result, message=f"{result.message}; {choice.statement()}")


def refit_setup(
    result: FitResult, initial: ParameterSet, options: FitOptions
) -> tuple[ParameterSet, FitOptions]:
    """The start and options that fit the structure ``result`` kept without choosing again
    (a cross-validation's folds): the larger model's start and options where it was kept."""
    choice = result.diagnostics.structure
    if choice is None or choice.chosen != choice.larger:
        return initial, replace(options, structure="as-given")
    return choice.start, replace(larger_options(options, choice.extra), progress=options.progress)
