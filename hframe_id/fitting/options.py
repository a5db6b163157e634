"""Options of a fit: which parameters are free, bounds, weights, transcription and solver.

Each link of the fitter's chain has its own frozen options (``ProblemOptions``,
``TranscriptionOptions``, ``SolverOptions``, ``StatisticsOptions``:
:mod:`hframe_id.fitting.link_options`). ``FitOptions``, the flat set a user gives, is
checked by building those parts and by its own checks of the strategy's settings. The
checks that need the model or the data (unknown parameter names, bounds that exclude the
initial value) run in :mod:`hframe_id.fitting.problem` before any solving starts.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

from hframe_id.errors import OptionError, shown
from hframe_id.fitting.gauss_newton_settings import GaussNewtonSettings
from hframe_id.fitting.link_options import (
    DEFAULT_CONTINUITY,
    DEFAULT_SHOOTING_INTERVAL,
    LINK_OPTIONS,
    ProblemOptions,
    SolverOptions,
    StatisticsOptions,
    TranscriptionOptions,
    default_threads,
)
from hframe_id.fitting.option_checks import changed_fields, one_of, positive
from hframe_id.fitting.strategy_settings import StrategySettings

NOISE_METHODS = ("auto", "sensor", "estimate")
#: How a fit treats a model that nests in a larger one (``FitOptions.structure``).
STRUCTURES = ("choose", "as-given")
#: The settings ``FitOptions`` may leave to the model (None), which ``for_model`` resolves:
#: those a model may declare ``fit_defaults`` for (``models.declaration.FIT_DEFAULT_KEYS``,
#: not imported here because that module imports CasADi; a test keeps the two equal).
LEFT_TO_MODEL = ("shooting_interval", "continuity")


@dataclass(frozen=True)
class FitProgress:
    """One line of progress, passed to ``FitOptions.progress``."""

    stage: str
    iteration: int
    cost: float
    step: float
    defect: float
    message: str = ""


def _part(options: Any, kind: type) -> Any:
    """The ``kind`` options (a dataclass whose fields are a subset of ``options``')."""
    return kind(**{f.name: getattr(options, f.name) for f in fields(kind)})


@dataclass(frozen=True)
class FitOptions:
    """How to fit: one flat set of options for users, validated on construction.

    The parts each component reads are its own frozen options (``problem_options``,
    ``transcription_options``, ``solver_options``, ``statistics_options``): the problem
    builder, the transcription, the solvers and the statistics see only theirs, and each
    part checks its fields (``FitOptions`` builds them to check its own); the rest (noise
    weighting, first stages, pre-pass, misfit limit, progress) is the fit's strategy.

    Attributes
    ----------
    free : parameter names or fnmatch patterns (``"k_*"``) to fit; ``None`` selects the
        variant's default: every stiffness, inertia, mass, viscous and Coulomb friction
        parameter and g_2 (everything but the declaration's ``fixed`` and ``held``; one-axis
        holds the unmeasured idler's J_2, B_2, tau_c2); the name ``"default"`` stands for
        that set among the others (``("default", "I_max")``).
    fix : names or patterns removed from the free set (applied after ``free``).
    bounds : ``{name: (low, high)}`` in SI units for free parameters (0 < low for the
        log-scale ones, 0 <= low for nonnegative ones). Default (``problem.default_bounds``):
        log-scale parameters [p0 / f, p0 f], nonnegative ones in ``zero_reachable``
        [0, p0 f], real ones p0 -/+ f |p0|, f the ``bound_factor``.
    bound_factor : default bound factor f (> 1). A fit that ends with a parameter on a default bound
        (not zero, not a given bound) is repeated with f squared, at most
        ``StrategySettings.box_widenings`` times: the default box is a guard for the exponential,
        not a statement about the rig, so it must not decide the answer.
    channel_std : ``{output name: std}`` [SI: the output's unit], the noise each residual is
        divided by. Default: encoder quantization step / sqrt(12) for angles, the rig's laser
        noise std for positions (both from the recording's rig metadata).
    recording_std : ``{output name: (std, ...)}`` [SI], one std per recording, in the order
        of the recordings: that output's residuals of each recording are divided by its own
        std (instead of ``channel_std``). What a fit that estimates its noise levels weighs
        with (``noise_rounds``): model error differs between recordings.
    latency_samples : ``{output name: samples}``, whole samples a sensor lags the plant
        (the laser's read-out latency, from its data sheet): the channel's sample k + d is
        compared with the model at sample k. Latency is not estimated: in steady motion a
        laser lagging the encoder is indistinguishable from belt stretch, and an unknown
        2-sample laser latency biased Coulomb friction 9x on the realistic rig
        (docs/fitting.md, "Model mismatch").
    consider : ``{name: relative std}`` of held parameters whose uncertainty the intervals
        include (consider covariance, ``hframe_id.fitting.consider``). ``None`` (default):
        the declaration's ``held`` table values and any parameter held for
        identifiability, each at ``HELD_PRIOR_RELATIVE_STD``; ``{}``: held values exact.
    consider_method : how the held priors enter: ``"linear"`` (the consider covariance
        linearised at the optimum), ``"refit"`` (two whole refits per held parameter, at
        exp(+/-sigma) times its value: the secant, for effects that are not linear) or
        ``"prior"`` (the held parameters are estimated with their prior as a Gaussian
        penalty on log p, centred on the start value: a maximum a posteriori fit, whose
        intervals are the posterior's; parameters held later for identifiability still get
        the linear consider covariance).
    solver : the solver of the all-window stages, by name (``hframe_id.fitting.solvers``,
        where others are registered): ``"gauss-newton"`` (default: the condensed
        Gauss-Newton of ``hframe_id.fitting.solver``), ``"ipopt"`` or ``"sqpmethod"`` (CasADi
        ``nlpsol`` with an exact Gauss-Newton Hessian on the same transcription,
        ``hframe_id.fitting.nlp``; IPOPT ~19x slower on the shipped six steps, reaching the
        same optimum). The start stages
        (equation error, moving windows) are Gauss-Newton either way.
    noise : how each channel is weighted. ``"sensor"``: by ``channel_std`` or the rig's
        noise model; ``"estimate"``: by noise levels estimated from the residuals (maximum
        likelihood with unknown channel variances, iterated, floored at the sensor's std);
        ``"auto"`` (default): estimated if the sensor-weighted fit does not reach the noise
        level (model mismatch, as on every real rig), else the sensor's.
    shooting_interval : samples per shooting window (a node every this many samples). None
        (default): the model's declared fit default (``fit_defaults``), else
        ``DEFAULT_SHOOTING_INTERVAL`` (10); see ``for_model``.
    continuity : None (default): the model's declared fit default, else ``"exact"``.
        ``"exact"``: the windows of an experiment join into one simulated
        trajectory (output error; the interval only shapes the path of the solver).
        ``"none"``: every window starts from its own estimated state and is simulated over
        ``shooting_interval`` samples only: a prediction-error fit on horizons of that
        length. For plants whose open-loop simulation drifts (integrators under closed-loop
        control, the EMPS axis): a short horizon limits the drift's bias, a long one the
        noise's influence (docs/real-data.md).
    initial_state : each recording's initial state. ``"auto"`` (default): at rest (every
        velocity zero and the belts unstretched, as ``hframe-id validate`` and ``simulate``
        start: ``rest_start``) where the record's first samples show rest
        (``dataset.starts_at_rest``), estimated where it starts in motion; ``"rest"``:
        every record at rest; ``"estimate"``: every initial state estimated. A free
        initial state can absorb model error that the written file, simulated from rest,
        then shows (issue 25).
    smoothing : final Coulomb smoothing velocities (linear [m/s], angular [rad/s]); default
        the model's (1e-3 m/s, 1e-2 rad/s).
    smoothing_schedule : continuation: factors applied to ``smoothing`` in the stages on the
        moving windows, decreasing, ending with 1. Default (1,): measured on this problem,
        a wider smoothing is a different model (a motor creeps under sub-Coulomb torque) that
        cannot follow the records at rest, and it did not make starts converge more often
        (docs/fitting.md).
    first_stage : start with the equation-error regression and the stages on the moving
        windows (see ``hframe_id.fitting.fit``); without them the full multiple-shooting
        problem starts from the initial parameters and measured nodes (converges only from
        good starts).
    state_prepass : for models with a coordinate no output measures (one-axis: the idler),
        first attempt the fit with the node states estimated at the parameters held
        (continuity as a penalty), then release the parameters; if that attempt does not
        converge, fit again from the measured nodes (docs/fitting.md, "One-axis").
    max_iterations : Gauss-Newton iterations per stage.
    gauss_newton : the Gauss-Newton iteration's tuning (trust region, watchdog, stall and
        give-up rules: ``hframe_id.fitting.gauss_newton_settings.GaussNewtonSettings``),
        for every Gauss-Newton stage of the fit; the defaults are the measured ones.
    step_tol : converged when no free parameter changes by more than this relative amount
        (and the continuity defects are below ``defect_tol``). 1e-7 is four orders below
        the 0.1 % scale of anything a test or a user compares.
    defect_tol : continuity defects, in units of the measurement noise, at convergence.
    identifiability_threshold : a free parameter whose relative standard error exceeds this
        is reported as not identified, fixed at its initial value and the fit re-solved.
    max_misfit : a converged fit whose residual rms exceeds this many standard deviations
        of the sensors' noise (``channel_std`` or the rig's specification; never a level
        estimated from the residuals) is reported as failed: a local optimum far from the
        data, or a model that cannot follow it. None (default): 5 (``local_fit.DEFAULT_MAX_MISFIT``:
        far above a correct fit on sim-rig data, 1.0-1.3, far below the wrong optima measured
        on one-axis data, 10-45) for a fit weighted by the sensors' noise, and no limit for
        one that estimated its noise levels (model mismatch, judged against the points the
        fit knows and stated with that evidence).
    uncertainty : ``"robust"`` (default): per parameter the larger of the ``"noise-model"``
        and ``"hac"`` errors; ``"noise-model"``: parametric bootstrap of the linearised
        estimator with the rig's noise model (encoder quantization, laser noise);
        ``"hac"``: Newey-West sandwich per channel and experiment; ``"gauss-newton"``: the
        textbook s^2 (J^T J)^-1, which understates the errors 5x here (quantization errors
        are not white). See ``hframe_id.fitting.statistics``.
    confidence : level of the reported intervals.
    substep_safety, max_substeps : RK4 substeps are chosen from the current parameters so
        |lambda| h <= 2.785 / safety (see ``hframe_id.simulation.integrators``), at most
        ``max_substeps``; a point where stability alone (|lambda| h <= 2.785) needs more is
        refused: no solver steps there, a start there fails saying so. The default 500
        covers the envelope of issue 25 (Coulomb friction 10 x and inertia 0.5 x Table 4.2:
        321 for stability, 481 with the safety 1.5, at 1 ms).
    threads : worker threads for evaluating shooting windows.
    rest_start : the first state of a record at rest. ``"rigid"`` (default): velocities zero,
        belts unstretched, the belt-free position estimated (``MultipleShooting.
        node_projector``); ``"replay"``: the replay's rest state (``validation.replay.
        rest_state``, what ``validate`` starts the record from), nothing estimated. The
        fit's stages take ``"rigid"`` and end with a solve under ``"replay"``
        (``local_fit``), so that what it reports is what ``validate`` reproduces.
    verbose : 0 silent, 1 one line per iteration (to ``progress`` or stderr).
    progress : callable receiving :class:`FitProgress` after every iteration.
    zero_reachable : nonnegative parameters (friction) fitted linearly from 0, which they
        may reach, in [0, p0 f]; the others are fitted in log scale in [p0 / f, p0 f] (better
        conditioned: measured 3.6 s against 27 s for the shipped six steps), and a fit that
        ends with one on its lower bound is repeated with it here (``strategy``).
        A nonnegative parameter starting at 0 is always fitted linearly.
    known_points : parameter sets of the fitted model (``hframe-id fit --known FILE``) the fit
        must not end worse than, besides its start, the equation-error estimate and the
        model's reference files (``hframe_id.fitting.known_points``).
    starts, start_seed : a multistart portfolio (``hframe_id.fitting.multistart``): the fit
        from ``initial`` and from ``starts - 1`` seeded draws around it (x/÷2 at most, one
        generator seeded with ``start_seed``), the best kept and how many reached it
        reported. 1 (default): the given start only.
    strategy : the stages' tuning (intermediate tolerances, pre-pass, fast path, noise
        rounds, box widenings, restarts, identifiability holds:
        ``hframe_id.fitting.strategy_settings.StrategySettings``); the defaults are the
        measured ones.
    screen_start : begin from the best of the start, the model's reference files and
        ``known_points`` by their simulation from rest (``hframe_id.fitting.start_screen``;
        default True); False: from the start as given.
    structure : ``"choose"`` (default): where the model nests in a larger one (hframe-8 in
        hframe-8-current-limit, ``ModelDeclaration.nests_in``), fit that one as well and keep
        the one the data choose (``hframe_id.fitting.structure_choice``); ``"as-given"``: the
        model of ``initial`` only.
    """

    free: tuple[str, ...] | None = None
    fix: tuple[str, ...] = ()
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    bound_factor: float = ProblemOptions.bound_factor
    channel_std: Mapping[str, float] = field(default_factory=dict)
    recording_std: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    solver: str = SolverOptions.solver
    noise: str = "auto"
    latency_samples: Mapping[str, int] = field(default_factory=dict)
    consider: Mapping[str, float] | None = None
    consider_method: str = ProblemOptions.consider_method
    shooting_interval: int | None = None
    continuity: str | None = None
    initial_state: str = ProblemOptions.initial_state
    smoothing: tuple[float, float] | None = None
    smoothing_schedule: tuple[float, ...] = (1.0,)
    first_stage: bool = True
    state_prepass: bool = True
    max_iterations: int = SolverOptions.max_iterations
    gauss_newton: GaussNewtonSettings = SolverOptions.gauss_newton
    step_tol: float = SolverOptions.step_tol
    defect_tol: float = SolverOptions.defect_tol
    identifiability_threshold: float = StatisticsOptions.identifiability_threshold
    max_misfit: float | None = None
    uncertainty: str = StatisticsOptions.uncertainty
    confidence: float = StatisticsOptions.confidence
    substep_safety: float = TranscriptionOptions.substep_safety
    max_substeps: int = TranscriptionOptions.max_substeps
    threads: int = field(default_factory=default_threads)
    rest_start: str = TranscriptionOptions.rest_start
    verbose: int = 0
    progress: Callable[[FitProgress], None] | None = None
    known_points: tuple[Any, ...] = ()  # ParameterSet objects
    zero_reachable: tuple[str, ...] = ()
    starts: int = 1
    screen_start: bool = True
    start_seed: int = 0
    structure: str = "choose"
    strategy: StrategySettings = StrategySettings()

    def __post_init__(self) -> None:
        self._check_links()
        self._check_smoothing_schedule()
        self._check_strategy()
        self._check_known_points()

    def _check_links(self) -> None:
        """Every field a link of the chain reads, checked by that link's options (each rule
        lives in the class that owns the field): the part of each link is built from the
        fields given here, and the values it normalises (sequences as tuples, smoothing as
        floats) are kept. A setting left to the model (None, ``LEFT_TO_MODEL``) is checked
        when ``for_model`` resolves it."""
        for kind in LINK_OPTIONS:
            given = {
                f.name: getattr(self, f.name)
                for f in fields(kind)
                if not (f.name in LEFT_TO_MODEL and getattr(self, f.name) is None)
            }
            part = kind(**given)
            for name in given:
                object.__setattr__(self, name, getattr(part, name))

    def _check_smoothing_schedule(self) -> None:
        """``smoothing_schedule``: factors > 0, not increasing, ending with 1; stored as a
        tuple of floats."""
        schedule = tuple(self.smoothing_schedule)
        if not schedule:
            raise OptionError("smoothing_schedule needs at least one factor (1.0)")
        for value in schedule:
            positive("smoothing_schedule factor", value)
        if any(b > a for a, b in zip(schedule, schedule[1:], strict=False)):
            raise OptionError(f"smoothing_schedule must not increase, got {shown(schedule)}")
        if schedule[-1] != 1:
            raise OptionError(
                f"smoothing_schedule must end with 1 (the final smoothing), got {shown(schedule)}"
            )
        object.__setattr__(self, "smoothing_schedule", tuple(float(v) for v in schedule))

    def _check_strategy(self) -> None:
        """The strategy's own settings: ``noise`` one of ``NOISE_METHODS``, ``structure`` one
        of ``STRUCTURES``, ``max_misfit`` None or > 0 [noise stds], ``starts`` a whole number
        > 0, ``start_seed`` an integer >= 0, ``verbose`` 0, 1 or 2, ``progress`` None or
        callable, ``strategy`` a ``StrategySettings``."""
        one_of("noise", self.noise, NOISE_METHODS)
        one_of("structure", self.structure, STRUCTURES)
        if self.max_misfit is not None:
            positive("max_misfit", self.max_misfit)
        positive("starts", self.starts, integer=True)
        if (
            isinstance(self.start_seed, bool)
            or not isinstance(self.start_seed, int)
            or (self.start_seed < 0)
        ):
            raise OptionError(f"start_seed must be an integer >= 0, got {shown(self.start_seed)}")
        if self.verbose not in (0, 1, 2):
            raise OptionError(f"verbose must be 0, 1 or 2, got {shown(self.verbose)}")
        if self.progress is not None and not callable(self.progress):
            raise OptionError("progress must be callable (FitProgress) -> None")
        if not isinstance(self.strategy, StrategySettings):
            raise OptionError(
                f"strategy must be StrategySettings, got {type(self.strategy).__name__}"
            )

    def _check_known_points(self) -> None:
        """``known_points``: ``ParameterSet`` objects, stored as a tuple."""
        from hframe_id.parameters import ParameterSet

        object.__setattr__(self, "known_points", tuple(self.known_points))
        for params in self.known_points:
            if not isinstance(params, ParameterSet):
                raise OptionError(
                    f"known_points must be ParameterSet objects, got {type(params).__name__}"
                )

    def for_model(self, variant: str) -> FitOptions:
        """These options with every setting left to the model (None) resolved: the
        declaration's ``fit_defaults`` (e.g. the EMPS axis: 50-sample prediction-error
        horizons), else the library's defaults. ``fit_recordings`` calls it, so a fit from
        Python runs what ``hframe-id fit`` runs."""
        from hframe_id.models import declaration

        declared = declaration(variant)
        defaults = {
            "shooting_interval": DEFAULT_SHOOTING_INTERVAL,
            "continuity": DEFAULT_CONTINUITY,
            **dict(declared.fit_defaults),
        }
        unset = {k: v for k, v in defaults.items() if getattr(self, k) is None}
        try:
            return replace(self, **unset)
        except OptionError as err:
            raise OptionError(f"{declared.source}: fit default: {err}") from None

    @property
    def problem_options(self) -> ProblemOptions:
        """The problem's part: free and fixed sets, bounds, channel noise levels, latency,
        friction smoothing."""
        return _part(self, ProblemOptions)

    @property
    def transcription_options(self) -> TranscriptionOptions:
        """The multiple-shooting transcription's part: shooting interval, continuity,
        substeps, threads. Only of options whose transcription is resolved (``for_model``):
        the model's declared ``fit_defaults`` are not the library's."""
        unset = [k for k in LEFT_TO_MODEL if getattr(self, k) is None]
        if unset:
            raise OptionError(
                f"{' and '.join(unset)} left to the model: take the transcription_options "
                "of for_model(variant)"
            )
        return _part(self, TranscriptionOptions)

    @property
    def solver_options(self) -> SolverOptions:
        """The solver's part: which solver, iteration limit, step and defect tolerances,
        the Gauss-Newton iteration's tuning."""
        return _part(self, SolverOptions)

    @property
    def statistics_options(self) -> StatisticsOptions:
        """The error estimates' part: method, confidence level, consider priors,
        identifiability threshold."""
        return _part(self, StatisticsOptions)

    def describe(self) -> dict[str, Any]:
        """The options as plain data for a fit's provenance."""
        return {
            "free": list(self.free) if self.free is not None else "default",
            "fix": list(self.fix),
            "bounds": {k: [float(a), float(b)] for k, (a, b) in self.bounds.items()},
            "bound_factor": float(self.bound_factor),
            "channel_std": {k: float(v) for k, v in self.channel_std.items()},
            "recording_std": {k: [float(x) for x in v] for k, v in self.recording_std.items()},
            "solver": self.solver,
            "noise": self.noise,
            "latency_samples": {k: int(v) for k, v in self.latency_samples.items()},
            "consider": "default" if self.consider is None else dict(self.consider),
            "consider_method": self.consider_method,
            "shooting_interval_samples": int(self.shooting_interval),
            "continuity": self.continuity,
            "initial_state": self.initial_state,
            "smoothing": list(self.smoothing) if self.smoothing else "model default",
            "smoothing_schedule": list(self.smoothing_schedule),
            "first_stage": bool(self.first_stage),
            "state_prepass": bool(self.state_prepass),
            "max_iterations": int(self.max_iterations),
            "gauss_newton": changed_fields(self.gauss_newton) or "default",
            "step_tol": float(self.step_tol),
            "defect_tol": float(self.defect_tol),
            "identifiability_threshold": float(self.identifiability_threshold),
            "max_misfit": None if self.max_misfit is None else float(self.max_misfit),
            "known_points": [p.title for p in self.known_points],
            "zero_reachable": list(self.zero_reachable),
            "starts": int(self.starts),
            "start_seed": int(self.start_seed),
            "screen_start": bool(self.screen_start),
            "strategy": changed_fields(self.strategy) or "default",
            "uncertainty": self.uncertainty,
            "confidence": float(self.confidence),
            "substep_safety": float(self.substep_safety),
            "max_substeps": int(self.max_substeps),
            "rest_start": self.rest_start,
        }
