"""What a fit produced: each parameter's estimate and interval, and the fit as a whole."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from hframe_id.fitting.consider import Consider
from hframe_id.fitting.known_points import KnownPointsReport
from hframe_id.fitting.multistart import StartOutcome
from hframe_id.fitting.multistart import statement as multistart_statement
from hframe_id.fitting.noise_rounds import NoiseReport
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.problem import FitProblem
from hframe_id.fitting.solver import StageReport
from hframe_id.fitting.start_screen import ScreenedStart
from hframe_id.fitting.statistics import Statistics
from hframe_id.fitting.structure_choice import StructureChoice
from hframe_id.parameters import ParameterSet


@dataclass(frozen=True)
class ParameterEstimate:
    """One parameter of a fit (SI units).

    ``std_error`` and ``ci95`` come from the covariance chosen in the options (robust to
    correlated residuals by default); the interval is symmetric in log(p), so it is
    [p / f, p * f] with f = exp(z * relative_std), except for signed parameters (offsets),
    fitted linearly, whose interval is p -/+ z std_error. Fixed parameters have zero error and
    ``free`` False; free parameters the data do not identify are held at their initial
    value, with ``identified`` False and the standard error they had when found out. A free
    parameter the box stopped has ``at_bound`` True, ``identified`` False (the bound, not the
    data, fixes it) and an interval that ends at the bound. After a leave-one-recording-out
    cross-validation, ``jackknife_std`` and ``jackknife_ci95`` are the experiment-level
    jackknife's (``fitting.jackknife``), which hold model error that differs between
    experiments; None without one. ``open_ended`` is ``"above"`` or ``"below"`` for a
    parameter on the widened default box that the data bound on the other side only
    (``fitting.open_ended``): its interval runs to infinity or 0.
    """

    name: str
    unit: str
    initial: float
    estimate: float
    std_error: float
    ci95: tuple[float, float]
    identified: bool
    free: bool
    relative_std: float = 0.0
    relative_std_gn: float = 0.0
    collinearity: float = 1.0
    at_bound: bool = False
    identified_by: tuple[str, ...] = ()
    jackknife_std: float | None = None
    jackknife_ci95: tuple[float, float] | None = None
    open_ended: str = ""

    @property
    def key(self) -> str:
        """``"name [unit]"``, as in parameter files and reports."""
        return f"{self.name} [{self.unit}]"


@dataclass(frozen=True)
class FitDiagnostics:
    """What a fit reports beside its estimates. Per output channel, by name, in the channel's
    SI unit (m or rad): ``channel_std`` the noise std the final solve weighed it with,
    ``channel_rms`` its residual rms over the valid samples. ``residual_rms_noise_std`` and
    ``residual_rms_sensor_std``: the residual rms over all valid samples in units of those
    weights' std and of the sensors' (dimensionless; nan where not computed).
    ``at_default_box``: free parameters that ended on the default box (drawn around the
    start, ``FitOptions.bound_factor``). ``noise``: how the channels were weighed
    (``noise_rounds.NoiseReport``); ``known_points``: the fit against the points it knows
    (``known_points.KnownPointsReport``); ``starts``: each start of a multistart portfolio
    (``multistart.StartOutcome``; empty without one); ``start_screen``: where the fit began
    (``start_screen.ScreenedStart``); ``consider``: what the intervals
    assume about held parameters (``consider.Consider``); ``structure``: which of two nested
    models the fit kept (``structure_choice.StructureChoice``). None where that step did not
    run."""

    channel_std: dict[str, float] = field(default_factory=dict)
    channel_rms: dict[str, float] = field(default_factory=dict)
    residual_rms_noise_std: float = math.nan
    residual_rms_sensor_std: float = math.nan
    at_default_box: tuple[str, ...] = ()
    noise: NoiseReport | None = None
    known_points: KnownPointsReport | None = None
    starts: tuple[StartOutcome, ...] = ()
    consider: Consider | None = None
    start_screen: ScreenedStart | None = None
    structure: StructureChoice | None = None


@dataclass(frozen=True)
class FitResult:
    """What a fit produced. ``parameters`` holds every parameter (fitted and fixed).
    Frozen: what changes it (intervals widened, a continuation, the jackknife) makes a new
    one (``dataclasses.replace``)."""

    success: bool
    message: str
    parameters: ParameterSet
    estimates: dict[str, ParameterEstimate]
    cost: float
    iterations: int
    wall_time_s: float
    correlation: np.ndarray
    free_names: tuple[str, ...]
    initial: ParameterSet
    options: FitOptions
    stages: list[StageReport] = field(default_factory=list)
    statistics: Statistics | None = None
    not_identified: tuple[str, ...] = ()
    initial_states: np.ndarray | None = None  # (experiments, n_x) estimated
    experiment_names: tuple[str, ...] = ()
    evaluations: int = 0
    problem: FitProblem | None = field(default=None, repr=False)
    #: (n_f,) theta of the equation-error estimate relative to ``problem``'s start (None: the
    #: fit had no first stage); a point the fit knows (``fit._known_candidates``).
    equation_error: np.ndarray | None = field(default=None, repr=False)
    diagnostics: FitDiagnostics = field(default_factory=FitDiagnostics)

    def with_diagnostics(self, **changes) -> FitResult:
        """This result with ``changes`` to its ``diagnostics`` (``FitDiagnostics`` fields)."""
        return replace(self, diagnostics=replace(self.diagnostics, **changes))

    def started_from(self, initial: ParameterSet) -> FitResult:
        """This result reporting ``initial`` as its start (a fit continued from a known
        point reports the user's start)."""
        if self.initial is initial:
            return self
        estimates = {
            name: replace(est, initial=float(initial.values[name]))
            for name, est in self.estimates.items()
        }
        return replace(self, initial=initial, estimates=estimates)

    @property
    def variant(self) -> str:
        """The model variant fitted."""
        return self.parameters.variant

    @property
    def has_jackknife(self) -> bool:
        """Whether a cross-validation gave any parameter its jackknife interval."""
        return any(est.jackknife_ci95 for est in self.estimates.values())

    @property
    def prior_names(self) -> tuple[str, ...]:
        """Free parameters estimated with a prior (``FitOptions.consider_method`` "prior")."""
        return self.problem.prior_names if self.problem is not None else ()

    @property
    def residual_rms(self) -> float:
        """Residual rms over the valid samples in units of the noise std the channels were
        weighted by (about 1 for a correct model on sim-rig data; about 1 by construction
        once the noise levels were estimated from the residuals)."""
        return float(self.diagnostics.residual_rms_noise_std)

    @property
    def residual_rms_sensor(self) -> float:
        """Residual rms over the valid samples in units of the sensors' noise std (the
        user's ``channel_std`` or the rig's specification): the misfit that a level estimated
        from the residuals cannot hide."""
        return float(self.diagnostics.residual_rms_sensor_std)

    def held_statement(self) -> str | None:
        """What the intervals assume about held parameters (None if nothing is held or
        estimated with a prior): which parameters, at which values, with which prior
        relative std, and how the prior entered."""
        consider = self.diagnostics.consider
        prior = consider.held_relative_std if consider is not None else {}
        sentences = []
        if self.prior_names:
            weights = dict(zip(self.problem.free_names, self.problem.prior_weight, strict=True))
            listed = ", ".join(
                f"{name} (start {self.initial.values[name]:.4g}, +/-{100 / weights[name]:.0f} %)"
                for name in self.prior_names
            )
            sentences.append(
                f"Estimated with a prior on the initial file's values (maximum a posteriori; "
                f"Gaussian in log p): {listed}. Their intervals, and the others', are the "
                f"posterior's: data and prior together."
            )
        if prior:
            held = ", ".join(
                f"{name} = {self.parameters.values[name]:.4g} (+/-{100 * std:.0f} %)"
                for name, std in prior.items()
            )
            how = (
                "the spread of whole refits with each held value at exp(+/-std) of itself"
                if consider.method == "refit"
                else "consider covariance, linearised at the optimum"
            )
            failed = consider.failed_refits
            caveat = (
                f" {len(failed)} of the refits did not converge: {'; '.join(failed)}."
                if failed
                else ""
            )
            sentences.append(
                f"Held at the initial file's values, not fitted: {held}. The intervals include "
                f"this prior uncertainty of the held values ({how}); they do not assume the "
                f"held values are exact.{caveat}"
            )
        return " ".join(sentences) or None

    @property
    def initial_state_statement(self) -> str | None:
        """Which recordings started at rest (their initial state known) and which had theirs
        estimated (``FitOptions.initial_state``)."""
        if self.problem is None:
            return None
        rest = [e.name for e in self.problem.experiments if e.at_rest]
        estimated = [e.name for e in self.problem.experiments if not e.at_rest]
        parts = [f"at rest: {', '.join(rest)}"] * bool(rest)
        parts += [f"estimated: {', '.join(estimated)}"] * bool(estimated)
        return "initial states " + "; ".join(parts)

    @property
    def known_points_statement(self) -> str | None:
        """The simulation criterion of the fit against the points it knows
        (``hframe_id.fitting.known_points``), or None if they were not compared."""
        report = self.diagnostics.known_points
        if report is None:
            return None
        others = report.compared
        label = min(others, key=others.get)
        return (
            f"{report.criterion}: replayed from the recordings' start as validate replays the "
            f"file, {report.replayed:.6g}; from the fit's initial states, {report.fit:.6g}, "
            f"and the best known point, {label}, {others[label]:.6g}"
        )

    @property
    def multistart_statement(self) -> str | None:
        """How many starts of a multistart portfolio reached the best optimum
        (``hframe_id.fitting.multistart``), or None without one."""
        starts = self.diagnostics.starts
        return multistart_statement(starts) if starts else None

    @property
    def search_statements(self) -> tuple[str | None, ...]:
        """Where the fit started and what it was compared with: the initial states, the
        known points, the multistart portfolio (None where not applicable)."""
        return (
            self.initial_state_statement,
            self.known_points_statement,
            self.multistart_statement,
        )

    def status_of(self, name: str) -> str:
        """The verdict on free parameter ``name``, in the words of the summary, the report
        and the mismatch statement: not assessed (the fit failed), not bounded on one side
        by the data, at a bound, identified, held, or poorly determined; with a prior."""
        est = self.estimates[name]
        if not self.success:
            status = "not assessed (fit failed)"
        elif est.open_ended:
            status = f"not bounded {est.open_ended} by the data (on the box, interval open)"
        elif est.at_bound:
            status = "at bound (the box fixes it; interval ends there)"
        elif est.identified:
            status = "identified"
        elif name in self.not_identified:
            status = "NOT identified (held at its initial value)"
        else:
            status = f"poorly determined (relative std {est.relative_std:.0%}, kept at estimate)"
        if name in self.prior_names:
            status += ", with a prior"
        return status

    def summary(self) -> str:
        """A one-screen table: parameter, initial, fitted, 95 % interval, the jackknife's
        95 % interval (after a cross-validation), status (identified, held, at bound, poorly
        determined); then the verdict line."""
        jackknife = self.has_jackknife
        extra = f" {'jackknife 95 % interval':>25}" if jackknife else ""
        lines = [
            f"{'parameter':<22} {'initial':>11} {'fitted':>11} {'95 % interval':>25}{extra}  status"
        ]
        for est in self.estimates.values():
            if not est.free:
                continue
            status = self.status_of(est.name)
            if jackknife:
                ci = est.jackknife_ci95
                extra = f" [{ci[0]:>10.5g}, {ci[1]:>10.5g}]" if ci else f" {'n/a':>25}"
            lines.append(
                f"{est.key:<22} {est.initial:>11.5g} {est.estimate:>11.5g} "
                f"[{est.ci95[0]:>10.5g}, {est.ci95[1]:>10.5g}]{extra}  {status}"
            )
        lines += [s for s in self.search_statements if s]
        lines.append(
            f"{'success' if self.success else 'FAILED'}: {self.message} "
            f"(cost {self.cost:.6g}, residual rms {self.residual_rms:.3g} x the weights' "
            f"noise std, {self.residual_rms_sensor:.3g} x the sensors', "
            f"{self.iterations} iterations in all stages, {self.wall_time_s:.2f} s)"
        )
        return "\n".join(lines)


def spread(
    value: float, theta_std: float, signed: bool, scale: float, z: float
) -> tuple[float, float, tuple[float, float]]:
    """(std error [SI], relative std, interval) of a free parameter from the std of its theta.

    Log-scale parameters: theta is a relative change, the interval symmetric in log(p),
    [p / f, p f] with f = exp(z std). Linear ones (``signed``: nonnegative and real kinds):
    p = p0 + s theta, the interval p -/+ z s std.
    """
    if signed:
        std = scale * theta_std
        return std, std / abs(value) if value else math.inf, (value - z * std, value + z * std)
    factor = math.exp(min(z * theta_std, 700.0))
    return value * theta_std, theta_std, (value / factor, value * factor)
