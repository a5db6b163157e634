"""The options of the fitter's links: each link of the chain (problem, transcription, solver,
statistics) has its own frozen options, checked on construction with a one-line message a
user can act on, so a link used on its own is checked too. ``FitOptions``
(:mod:`hframe_id.fitting.options`), the flat set a user gives, builds them.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from hframe_id.errors import OptionError, shown
from hframe_id.fitting.gauss_newton_settings import GaussNewtonSettings
from hframe_id.fitting.option_checks import as_tuple, names, one_of, positive
from hframe_id.fitting.solvers import check_solver_name

#: Prior relative std of a table value held in a fit (``FitOptions.consider``): the spread
#: between the thesis's own tables and between rigs is 10-20 % (Tables 2.1/2.3, 4.1/4.2).
HELD_PRIOR_RELATIVE_STD = 0.2

UNCERTAINTY_METHODS = ("robust", "noise-model", "hac", "gauss-newton")
CONTINUITY = ("exact", "none")
#: Transcription of a model that declares no ``fit_defaults``: windows of 10 samples (a
#: node every 10 ms at 1 kHz) joined into one simulated trajectory.
DEFAULT_SHOOTING_INTERVAL = 10
DEFAULT_CONTINUITY = "exact"
INITIAL_STATES = ("auto", "rest", "estimate")
REST_STARTS = ("rigid", "replay")
CONSIDER_METHODS = ("linear", "refit", "prior")


def _check_consider(consider: Any, consider_method: Any) -> None:
    """``consider``: None or a mapping of names to relative stds > 0 [1];
    ``consider_method`` one of ``CONSIDER_METHODS``. Read by the problem (``"prior"``: the
    held parameters' priors enter the cost) and by the statistics (the consider covariance)."""
    if consider is not None:
        if not isinstance(consider, Mapping):
            raise OptionError(
                f"consider must map parameter names to relative std, got {shown(consider)}"
            )
        for name, value in consider.items():
            positive(f"consider[{shown(name)}]", value)
    one_of("consider_method", consider_method, CONSIDER_METHODS)


def default_threads() -> int:
    """Worker threads for the shooting windows: the cores, at most 8."""
    return max(1, min(os.cpu_count() or 1, 8))


@dataclass(frozen=True)
class ProblemOptions:
    """What is estimated, from what: the parts of ``FitOptions`` that ``build_problem`` reads
    (free set, bounds, channel weights and latencies, Coulomb smoothing, and the held
    parameters' priors where they enter the cost).

    The fields mean what ``FitOptions``' of the same name do, with the same defaults; each is
    checked on construction (the names of parameters and outputs against the model only when
    the problem is built), the sequences stored as tuples."""

    free: tuple[str, ...] | None = None
    fix: tuple[str, ...] = ()
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    bound_factor: float = 10.0
    channel_std: Mapping[str, float] = field(default_factory=dict)
    recording_std: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    latency_samples: Mapping[str, int] = field(default_factory=dict)
    smoothing: tuple[float, float] | None = None
    consider: Mapping[str, float] | None = None
    consider_method: str = "linear"
    initial_state: str = "auto"
    zero_reachable: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        self._check_names()
        self._check_bounds()
        self._check_channels()
        self._check_smoothing()
        _check_consider(self.consider, self.consider_method)
        one_of("initial_state", self.initial_state, INITIAL_STATES)

    def _check_names(self) -> None:
        """``free`` (None: the model's default set, else not empty), ``fix`` and
        ``zero_reachable``: sequences of non-empty names, stored as tuples."""
        if self.free is not None:
            object.__setattr__(self, "free", names("free", self.free))
            if not self.free:
                raise OptionError("free must name at least one parameter (or be None for defaults)")
        object.__setattr__(self, "fix", names("fix", self.fix))
        object.__setattr__(self, "zero_reachable", names("zero_reachable", self.zero_reachable))

    def _check_bounds(self) -> None:
        """``bounds``: a mapping of names to two numbers, low < high [SI]; ``bound_factor``
        a number > 1."""
        if not isinstance(self.bounds, Mapping):
            raise OptionError(f"bounds must map names to (low, high), got {shown(self.bounds)}")
        for name, pair in self.bounds.items():
            if not (isinstance(pair, tuple | list) and len(pair) == 2):
                raise OptionError(f"bounds[{shown(name)}] must be (low, high), got {shown(pair)}")
            low, high = pair
            for v in (low, high):
                if isinstance(v, bool) or not isinstance(v, int | float) or math.isnan(v):
                    raise OptionError(
                        f"bounds[{shown(name)}] must be two numbers, got {shown(pair)}"
                    )
            if not low < high:
                raise OptionError(
                    f"bounds[{shown(name)}] must satisfy low < high, got {shown(pair)}"
                )
        positive("bound_factor", self.bound_factor)
        if self.bound_factor <= 1:
            raise OptionError(f"bound_factor must be > 1, got {shown(self.bound_factor)}")

    def _check_channels(self) -> None:
        """``channel_std``: output names to noise stds > 0 [rad or m]; ``recording_std``:
        output names to one such std per recording, stored as tuples; ``latency_samples``:
        output names to whole numbers in 0..100 [samples]."""
        if not isinstance(self.channel_std, Mapping):
            raise OptionError(
                f"channel_std must map output names to numbers, got {shown(self.channel_std)}"
            )
        for name, value in self.channel_std.items():
            positive(f"channel_std[{shown(name)}]", value)
        if not isinstance(self.recording_std, Mapping):
            raise OptionError(
                "recording_std must map output names to one number per recording, "
                f"got {shown(self.recording_std)}"
            )
        per_recording = {}
        for name, values in self.recording_std.items():
            if isinstance(values, str) or not isinstance(values, Sequence) or not values:
                raise OptionError(
                    f"recording_std[{shown(name)}] must be one number per recording, "
                    f"got {shown(values)}"
                )
            for k, value in enumerate(values):
                positive(f"recording_std[{shown(name)}][{k}]", value)
            per_recording[name] = tuple(float(v) for v in values)
        object.__setattr__(self, "recording_std", per_recording)
        checked_latency(self.latency_samples)

    def _check_smoothing(self) -> None:
        """``smoothing``: None or two velocities > 0 [m/s, rad/s], stored as floats."""
        if self.smoothing is None:
            return
        pair = None if isinstance(self.smoothing, str) else as_tuple(self.smoothing)
        if pair is None or len(pair) != 2:
            raise OptionError(
                f"smoothing must be (linear m/s, angular rad/s), got {shown(self.smoothing)}"
            )
        for value in pair:
            positive("smoothing", value)
        object.__setattr__(self, "smoothing", tuple(float(v) for v in pair))


@dataclass(frozen=True)
class TranscriptionOptions:
    """How the problem is cut into shooting windows and integrated: the parts of
    ``FitOptions`` that ``MultipleShooting`` reads, each checked on construction. The fields
    mean what ``FitOptions``' do; the defaults are the library's for a model that declares
    no ``fit_defaults`` (``FitOptions.for_model`` applies a model's)."""

    shooting_interval: int = DEFAULT_SHOOTING_INTERVAL
    continuity: str = DEFAULT_CONTINUITY
    substep_safety: float = 1.5
    max_substeps: int = 500
    threads: int = field(default_factory=default_threads)
    rest_start: str = "rigid"

    def __post_init__(self) -> None:
        if (
            isinstance(self.shooting_interval, bool)
            or not isinstance(self.shooting_interval, int)
            or self.shooting_interval < 1
        ):
            raise OptionError(
                f"shooting interval must be >= 1 sample, got {shown(self.shooting_interval)}"
            )
        one_of("continuity", self.continuity, CONTINUITY)
        one_of("rest_start", self.rest_start, REST_STARTS)
        positive("substep_safety", self.substep_safety)
        if self.substep_safety < 1:
            raise OptionError(f"substep_safety must be >= 1, got {shown(self.substep_safety)}")
        positive("max_substeps", self.max_substeps, integer=True)
        positive("threads", self.threads, integer=True)


@dataclass(frozen=True)
class SolverOptions:
    """How the all-window stages are solved: which solver (a name ``fitting.solvers``
    knows, built in or registered), iterations and tolerances (finite, > 0), and the
    Gauss-Newton iteration's tuning, each checked on construction. The fields mean what
    ``FitOptions``' do, with the same defaults."""

    solver: str = "gauss-newton"
    max_iterations: int = 150
    step_tol: float = 1e-6
    defect_tol: float = 1e-2
    gauss_newton: GaussNewtonSettings = GaussNewtonSettings()

    def __post_init__(self) -> None:
        check_solver_name(self.solver)
        if not isinstance(self.gauss_newton, GaussNewtonSettings):
            raise OptionError(
                f"gauss_newton must be GaussNewtonSettings, got {type(self.gauss_newton).__name__}"
            )
        positive("max_iterations", self.max_iterations, integer=True)
        positive("step_tol", self.step_tol)
        positive("defect_tol", self.defect_tol)


@dataclass(frozen=True)
class StatisticsOptions:
    """How the intervals are computed and judged, each field checked on construction. The
    fields mean what ``FitOptions``' do, with the same defaults."""

    uncertainty: str = "robust"
    confidence: float = 0.95
    consider: Mapping[str, float] | None = None
    consider_method: str = "linear"
    identifiability_threshold: float = 0.1

    def __post_init__(self) -> None:
        one_of("uncertainty", self.uncertainty, UNCERTAINTY_METHODS)
        if not (isinstance(self.confidence, float) and 0 < self.confidence < 1):
            raise OptionError(f"confidence must be in (0, 1), got {shown(self.confidence)}")
        _check_consider(self.consider, self.consider_method)
        positive("identifiability_threshold", self.identifiability_threshold)


#: The links of the chain, each handed its part of ``FitOptions``.
LINK_OPTIONS = (ProblemOptions, TranscriptionOptions, SolverOptions, StatisticsOptions)


def checked_latency(latency: object) -> dict[str, int]:
    """``latency_samples`` (output name -> whole samples in 0..100 a sensor lags the plant)
    as a dict; ``OptionError`` naming the entry that is not."""
    if not isinstance(latency, Mapping):
        raise OptionError(f"latency_samples must map output names to samples, got {shown(latency)}")
    for name, value in latency.items():
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 100:
            raise OptionError(
                f"latency_samples[{shown(name)}] must be a whole number of samples in 0..100, "
                f"got {shown(value)}"
            )
    return {str(name): int(value) for name, value in latency.items()}
