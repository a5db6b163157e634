"""The fitting problem: data + model + free parameters + cost, checked before any solving.

A fit is a weighted output-error least-squares problem over one or more experiments:

    min  1/2 sum_e sum_k sum_j  w_j^2 (y_j(t_k; x0_e, p) - y_meas_j,k)^2    over x0_e, p_free

with w_j = 1 / std_j (encoder quantization step / sqrt(12), laser noise), invalid samples left
out, free parameters in log scale, theta = ln(p / p_initial), within bounds. The recordings
on the model's channels are prepared in :mod:`hframe_id.fitting.dataset`; the
transcription (multiple shooting) and the solver (Gauss-Newton) live in their own modules.
"""

from __future__ import annotations

import difflib
import fnmatch
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from hframe_id.errors import FitError
from hframe_id.fitting.dataset import Dataset
from hframe_id.fitting.experiment import check_rigs, encoder_step
from hframe_id.fitting.link_options import HELD_PRIOR_RELATIVE_STD, ProblemOptions
from hframe_id.fitting.options import FitOptions
from hframe_id.models import Model, build_model
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording

#: A window needs at least this many valid output values per free quantity it brings; a
#: whole record needs this many valid values per estimated quantity (states + parameters).
MIN_VALID_PER_UNKNOWN = 5


@dataclass(frozen=True)
class FitProblem:
    """What is estimated, from what: model, free parameters and their spaces and bounds,
    the experiments and their weights (the cost), validated. No transcription, solver or
    strategy settings: those are the ``MultipleShooting``'s (``TranscriptionOptions``), the
    solver's (``SolverOptions``) and the fit's (``FitOptions``)."""

    model: Model
    initial: ParameterSet
    p_initial: np.ndarray  # all parameters, model order, SI
    free: tuple[int, ...]  # indices of free parameters in model order
    theta_lower: np.ndarray  # bounds on theta (``parameters``), free parameters
    theta_upper: np.ndarray
    #: (n_f,) True for free parameters fitted linearly (real ones; nonnegative ones from a
    #: start at 0 or named in ``FitOptions.zero_reachable``), False for log scale
    linear: np.ndarray
    #: (n_f,) True where that bound is the default box (``ProblemOptions.bound_factor``):
    #: neither a physical limit (0 of a nonnegative parameter) nor the user's ``bounds``
    box_lower: np.ndarray
    box_upper: np.ndarray
    experiments: tuple[Dataset, ...]
    channel_std: np.ndarray  # (n_y,) [SI]
    #: (n_experiments, n_y) [SI] the std each experiment's residuals are divided by: its own
    #: level where ``ProblemOptions.recording_std`` gives one, else ``channel_std``
    recording_std: np.ndarray
    quantization: np.ndarray  # (n_y,) encoder step [rad] of quantized channels, else 0
    sample_period_s: float
    smoothing: tuple[float, float]
    #: what is estimated, from what (``FitOptions.problem_options``): free set, bounds,
    #: channel noise, latency, priors; no transcription, solver or strategy settings
    problem_options: ProblemOptions
    #: (n_f,) weight 1 / sigma of each free parameter's Gaussian prior on theta, centred on
    #: the start value (theta = 0): the residual w theta (0: no prior;
    #: ``FitOptions.consider_method`` "prior")
    prior_weight: np.ndarray

    @property
    def free_names(self) -> tuple[str, ...]:
        """Names of the free parameters, in the order of ``theta``."""
        return tuple(self.model.parameters[i].name for i in self.free)

    @property
    def output_names(self) -> tuple[str, ...]:
        """Names of the model's outputs (the residual channels)."""
        return tuple(s.name for s in self.model.outputs)

    @property
    def prior_names(self) -> tuple[str, ...]:
        """Free parameters estimated with a prior (``FitOptions.consider_method`` "prior")."""
        return tuple(n for n, w in zip(self.free_names, self.prior_weight, strict=True) if w > 0)

    @property
    def linear_scale(self) -> np.ndarray:
        """(n_f,) scale s of the linear transform of linear parameters: |p_initial|, or 1 (SI)
        for a start at 0 (unused for log-scale parameters)."""
        start = np.abs(self.p_initial[list(self.free)])
        return np.where(start > 0, start, 1.0)

    def parameters(self, theta: np.ndarray) -> np.ndarray:
        """All parameters (SI, model order) for theta of the free ones.

        theta = ln(p / p_initial) for positive parameters (relative changes), and
        theta = (p - p_initial) / s for linear ones (``linear_scale``), so that theta is a
        relative change for both near the start, and a nonnegative parameter reaches 0 at
        theta = -p_initial / s.
        """
        p = self.p_initial.copy()
        start = self.p_initial[list(self.free)]
        p[list(self.free)] = np.where(
            self.linear, start + self.linear_scale * theta, start * np.exp(theta)
        )
        return p

    def parameter_set(self, theta: np.ndarray) -> ParameterSet:
        """The start's parameter set (``initial``) with every parameter at its value for
        theta (``parameters``; the fixed ones as they are)."""
        values = self.parameters(theta)
        return self.initial.replace_values(
            **{n: float(v) for n, v in zip(self.model.parameter_names, values, strict=True)}
        )

    def theta_of(self, params: ParameterSet) -> np.ndarray:
        """(n_f,) theta of the free parameters' values in ``params`` (the inverse of
        ``parameters``)."""
        p = np.array([params.values[n] for n in self.model.parameter_names])[list(self.free)]
        start = self.p_initial[list(self.free)]
        # Linear parameters may start at 0 (0 / 0): their log is computed and not used.
        with np.errstate(divide="ignore", invalid="ignore"):
            logs = np.log(np.abs(p / start))
        return np.where(self.linear, (p - start) / self.linear_scale, logs)

    def parameter_slopes(self, p: np.ndarray) -> np.ndarray:
        """(n_f,) d p / d theta of the free parameters at all parameters ``p`` (SI, model
        order): p itself for log scale, s for linear ones."""
        return np.where(self.linear, self.linear_scale, p[list(self.free)])

    @property
    def zero_floor(self) -> np.ndarray:
        """(n_f,) True for nonnegative free parameters whose lower bound is the physical 0
        (not a bound the user gave): an estimate there is zero, not stopped by a box."""
        given = self.problem_options.bounds
        return np.array(
            [
                self.model.parameters[i].kind == "nonnegative"
                and self.model.parameters[i].name not in given
                and straight
                for i, straight in zip(self.free, self.linear, strict=True)
            ],
            dtype=bool,
        )

    def on_box(self, theta: np.ndarray) -> np.ndarray:
        """(n_f,) True where the bound nearer to a free parameter's ``theta`` belongs to the
        default box (``box_lower``/``box_upper``): for parameters found at a bound, whether
        the default box, not the data, physics or the user, decided the value."""
        lower_nearer = theta - self.theta_lower < self.theta_upper - theta
        return np.where(lower_nearer, self.box_lower, self.box_upper)


def _suggest(word: str, choices: Sequence[str]) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.5)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _expand(patterns: Sequence[str], names: Sequence[str], what: str) -> list[str]:
    selected: list[str] = []
    for pattern in patterns:
        matches = fnmatch.filter(names, pattern)
        if not matches:
            raise FitError(
                f"{what}: no parameter matches {pattern!r}{_suggest(pattern, names)}; "
                f"valid: {', '.join(names)}"
            )
        selected += [m for m in matches if m not in selected]
    return selected


def default_free(model: Model) -> list[str]:
    """The declaration's default free set among the model's parameters: all but the measured
    (``fixed``) and the ``held`` ones (one-axis holds the unmeasured idler pulley)."""
    free = model.declaration.default_free()
    return [name for name in model.parameter_names if name in free]


#: In ``FitOptions.free``, the declaration's default free set (``default_free``), so that
#: one more parameter is freed without listing the others: ``("default", "I_max")``.
DEFAULT_FREE = "default"


def resolve_free(model: Model, options: ProblemOptions) -> list[str]:
    """The free parameter names: ``options.free`` (names or patterns, ``DEFAULT_FREE`` for the
    declaration's free set; default that set) without ``options.fix``; ``FitError`` if none
    are left."""
    names = list(model.parameter_names)
    free = _expand_free(options.free, model) if options.free else default_free(model)
    fixed = _expand(options.fix, names, "fix") if options.fix else []
    free = [n for n in free if n not in fixed]
    if not free:
        raise FitError("no free parameters left after --fix; nothing to fit")
    return free


def _expand_free(patterns: Sequence[str], model: Model) -> list[str]:
    """``_expand`` of the free patterns, ``DEFAULT_FREE`` standing for ``default_free``
    (a parameter of that name, in a user's model, is meant by it instead)."""
    names = list(model.parameter_names)
    if DEFAULT_FREE not in names:
        patterns = [
            name
            for pattern in patterns
            for name in (default_free(model) if pattern == DEFAULT_FREE else [pattern])
        ]
    return _expand(patterns, names, "free")


def consider_priors(model: Model, consider: Mapping[str, float] | None) -> dict[str, float]:
    """``{name: prior relative std}`` of ``FitOptions.consider``: as given, or by default the
    declaration's ``held`` parameters at ``HELD_PRIOR_RELATIVE_STD``; ``FitError`` for a name
    the model does not have."""
    names = list(model.parameter_names)
    if consider is None:
        return {n: HELD_PRIOR_RELATIVE_STD for n in model.declaration.held if n in names}
    unknown = [n for n in consider if n not in names]
    if unknown:
        raise FitError(f"consider: unknown parameter(s) {', '.join(unknown)}")
    return dict(consider)


def held_priors(model: Model, options: ProblemOptions) -> dict[str, float]:
    """``{name: relative std}`` of the held parameters estimated with a prior: with
    ``consider_method`` "prior", the ``consider_priors`` without the ``options.fix`` names;
    else none."""
    if options.consider_method != "prior":
        return {}
    priors = consider_priors(model, options.consider)
    fixed = _expand(options.fix, list(model.parameter_names), "fix") if options.fix else []
    return {n: s for n, s in priors.items() if n not in fixed}


def _with_initial_state(dataset: Dataset, sensor_std: np.ndarray, options) -> Dataset:
    """``dataset`` marked at rest (``Dataset.at_rest``) per ``options.initial_state``:
    always ("rest"), never ("estimate"), or where its first ``REST_SAMPLES`` show rest with
    the sensors' noise ``sensor_std`` [SI] ("auto"; ``Dataset.shows_rest``, the test
    ``hframe-id validate`` applies)."""
    if options.initial_state != "auto":
        return replace(dataset, at_rest=options.initial_state == "rest")
    return replace(dataset, at_rest=dataset.shows_rest(sensor_std))


def build_problem(
    recordings: Sequence[Recording], initial: ParameterSet, options: FitOptions
) -> FitProblem:
    """Check the data and options against the model and assemble the problem, which keeps
    the options' ``problem_options`` (the shooting interval is checked against the records
    here, before any solving, but belongs to the transcription).

    Raises ``FitError`` (before any solving) for: no recordings, mixed variants or rigs,
    unknown free parameter names (suggesting the nearest), a free parameter at zero (log
    scale), bounds excluding the initial value, too few valid samples, an output with no
    valid sample, a shooting interval not shorter than a record.
    """
    recordings = _checked_inputs(recordings, initial)
    model = build_model(initial.variant)
    options = options.for_model(initial.variant)
    wanted = options.problem_options  # what the problem keeps
    _check_channels(model, initial, recordings[0])
    p0 = model.parameter_vector(initial.values)
    names = list(model.parameter_names)
    free_names, priors = _free_set(model, wanted)
    spaces = _parameter_spaces(model, p0, free_names, wanted)
    free = tuple(names.index(n) for n in free_names)
    experiments = _experiments(recordings, model, options.shooting_interval, wanted)
    # The first recording's sensors weigh every channel (the recordings share one rig).
    first = experiments[0]
    std = np.array(
        [
            wanted.channel_std.get(name) or sensor
            for name, sensor in zip(first.names, first.noise_std, strict=True)
        ]
    )
    experiments = tuple(_with_initial_state(e, first.noise_std, wanted) for e in experiments)
    recording_std = np.array(
        [
            [
                wanted.recording_std[name][e] if name in wanted.recording_std else std[j]
                for j, name in enumerate(first.names)
            ]
            for e in range(len(experiments))
        ]
    )
    # Only an angle the output is (not a speed or a current named phi...) is an encoder's.
    quantization = np.array(
        [
            encoder_step(recordings[0], name) if kind == "position" else 0.0
            for name, kind in zip(first.names, first.kinds, strict=True)
        ]
    )
    _check_sample_counts(model, experiments, len(free))
    smoothing = wanted.smoothing or model.options.smoothing
    return FitProblem(
        model=model,
        initial=initial,
        p_initial=p0,
        free=free,
        **spaces,
        experiments=experiments,
        channel_std=std,
        recording_std=recording_std,
        quantization=quantization,
        sample_period_s=float(recordings[0].sample_period_s),
        smoothing=(float(smoothing[0]), float(smoothing[1])),
        problem_options=wanted,
        prior_weight=np.array([1.0 / priors[n] if n in priors else 0.0 for n in free_names]),
    )


def _checked_inputs(recordings: Sequence[Recording], initial: ParameterSet) -> list[Recording]:
    """The ``recordings`` as a list: at least one, every one a ``Recording`` of one rig
    (``check_rigs``), and ``initial`` a ``ParameterSet``; else ``FitError``."""
    recordings = list(recordings)
    if not recordings:
        raise FitError("no recordings to fit")
    for rec in recordings:
        if not isinstance(rec, Recording):
            raise FitError(f"expected Recording objects, got {type(rec).__name__}")
    check_rigs(recordings)
    if not isinstance(initial, ParameterSet):
        raise FitError(f"initial must be a ParameterSet, got {type(initial).__name__}")
    return recordings


def _check_channels(model: Model, initial: ParameterSet, rec: Recording) -> None:
    """``FitError`` if ``initial`` is of another variant than the recording ``rec`` and its
    ``model`` has other inputs, or outputs the recording lacks."""
    if initial.variant == rec.variant:
        return
    # A different model of the same rig is fine if it has the same inputs and outputs
    # (hframe-20 on hframe-8 records: phi1, phi2, x, y from u1, u2).
    if tuple(rec.input_names) != tuple(s.name for s in model.inputs) or not set(
        s.name for s in model.outputs
    ) <= set(rec.output_names):
        raise FitError(
            f"initial parameters are for {initial.variant} but the recordings are "
            f"{rec.variant} data ({rec.name()}), with other inputs or outputs"
        )


def _free_set(model: Model, wanted: ProblemOptions) -> tuple[list[str], dict[str, float]]:
    """The free parameter names in model order (``resolve_free``, and the held ones estimated
    with a prior) and those priors ``{name: relative std}`` (``held_priors``); ``FitError``
    for ``bounds`` or ``zero_reachable`` naming an unknown, not free or not nonnegative
    parameter."""
    names = list(model.parameter_names)
    free_names = resolve_free(model, wanted)
    priors = held_priors(model, wanted)
    if set(priors) - set(free_names):
        free_names = [n for n in names if n in free_names or n in priors]
    for name in wanted.bounds:
        if name not in names:
            raise FitError(f"bounds: unknown parameter {name!r}{_suggest(name, names)}")
        if name not in free_names:
            raise FitError(f"bounds given for {name!r}, which is not free")
    for name in wanted.zero_reachable:
        if name not in names:
            raise FitError(f"zero_reachable: unknown parameter {name!r}{_suggest(name, names)}")
        if model.parameters[names.index(name)].kind != "nonnegative":
            raise FitError(
                f"zero_reachable: {name} is not a nonnegative parameter (friction), which "
                "alone may reach 0"
            )
    return free_names, priors


def _parameter_spaces(
    model: Model, p0: np.ndarray, free_names: Sequence[str], wanted: ProblemOptions
) -> dict[str, np.ndarray]:
    """The ``FitProblem`` fields ``theta_lower``, ``theta_upper``, ``box_lower``,
    ``box_upper`` and ``linear`` of the free parameters starting at ``p0`` (SI, model order):
    each in log scale or linear, its bounds (``bounds``, else ``default_bounds``) on theta.
    ``FitError`` for a start or bounds its scale cannot take."""
    names = list(model.parameter_names)
    lower, upper, box_lower, box_upper, linear = [], [], [], [], []
    for name in free_names:
        value = p0[names.index(name)]
        kind = model.parameters[names.index(name)].kind
        if kind == "positive" and not value > 0:
            raise FitError(
                f"free parameter {name} starts at {float(value)!r}; a positive parameter is "
                f"fitted in log scale, so a free one needs a start > 0 (give a small positive "
                "value)"
            )
        if kind == "nonnegative" and not value >= 0:
            raise FitError(f"free parameter {name} starts at {float(value)!r}; it must be >= 0")
        straight = kind == "real" or (
            kind == "nonnegative" and (value == 0 or name in wanted.zero_reachable)
        )
        linear.append(straight)
        low, high = default_bounds(kind, value, wanted.bound_factor, straight)
        given = name in wanted.bounds
        if given:
            low, high = wanted.bounds[name]
        if not straight and not low > 0:
            raise FitError(
                f"bounds for {name} [{low:g}, {high:g}]: a parameter fitted in log scale needs "
                "0 < low (a nonnegative one reaches 0 in zero_reachable / --zero-reachable)"
            )
        if kind == "nonnegative" and not low >= 0:
            raise FitError(
                f"bounds for {name} [{low:g}, {high:g}]: a {kind} parameter needs 0 <= low"
            )
        if not low <= value <= high:
            raise FitError(
                f"bounds for {name} [{low:g}, {high:g}] exclude its initial value {value:g}"
            )
        if not straight:
            lower.append(math.log(low / value))
            upper.append(math.log(high / value))
        else:
            scale = abs(value) if value != 0 else 1.0
            lower.append((low - value) / scale)
            upper.append((high - value) / scale)
        box_lower.append(not given and not (kind == "nonnegative" and straight))
        box_upper.append(not given)
    return {
        "theta_lower": np.array(lower),
        "theta_upper": np.array(upper),
        "box_lower": np.array(box_lower, dtype=bool),
        "box_upper": np.array(box_upper, dtype=bool),
        "linear": np.array(linear, dtype=bool),
    }


def _experiments(
    recordings: Sequence[Recording], model: Model, shooting_interval: int, wanted: ProblemOptions
) -> tuple[Dataset, ...]:
    """The recordings on the model's channels (``Dataset.from_recording``) advanced by their
    ``latency_samples`` (``Dataset.delayed``); ``FitError`` for ``channel_std`` or
    ``latency_samples`` naming no output, a record not longer than a ``shooting_interval``
    [samples], or an output with no valid sample."""
    outputs = [s.name for s in model.outputs]
    for option in ("channel_std", "recording_std", "latency_samples"):
        for name in getattr(wanted, option):
            if name not in outputs:
                raise FitError(
                    f"{option}: unknown output {name!r}{_suggest(name, outputs)}; "
                    f"valid: {', '.join(outputs)}"
                )
    for name, values in wanted.recording_std.items():
        if len(values) != len(recordings):
            raise FitError(
                f"recording_std[{name!r}]: {len(values)} values for {len(recordings)} recordings"
            )
    latency = dict(wanted.latency_samples)
    experiments = tuple(Dataset.from_recording(model, rec).delayed(latency) for rec in recordings)
    for e in experiments:
        if shooting_interval >= len(e.valid):
            raise FitError(
                f"{e.name}: shooting interval of {shooting_interval} samples, but the "
                f"record has {len(e.valid)} samples"
            )
        empty = [name for j, name in enumerate(outputs) if not e.valid[:, j].any()]
        if empty:
            raise FitError(f"{e.name}: no valid sample of output {', '.join(empty)}")
    return experiments


def _check_sample_counts(model: Model, experiments: Sequence[Dataset], n_free: int) -> None:
    """``FitError`` unless every experiment, and all of them together, have
    ``MIN_VALID_PER_UNKNOWN`` valid output values per quantity they estimate (the initial
    states, and the ``n_free`` free parameters)."""
    n_unknown = model.n_states * len(experiments) + n_free
    n_valid = int(sum(e.valid.sum() for e in experiments))
    for e in experiments:
        if e.valid.sum() < MIN_VALID_PER_UNKNOWN * model.n_states:
            raise FitError(
                f"{e.name}: only {int(e.valid.sum())} valid output samples; a recording needs "
                f"at least {MIN_VALID_PER_UNKNOWN * model.n_states} to be worth fitting"
            )
    if n_valid < MIN_VALID_PER_UNKNOWN * n_unknown:
        raise FitError(
            f"too few valid samples: {n_valid} output values for {n_unknown} unknowns "
            f"(need >= {MIN_VALID_PER_UNKNOWN} per unknown)"
        )


def default_bounds(
    kind: str, value: float, factor: float, linear: bool = False
) -> tuple[float, float]:
    """The default box of a free parameter starting at ``value`` [SI]: [value / f, value f]
    in log scale (positive, and nonnegative unless ``linear``), [0, value f] for a
    nonnegative one fitted linearly (zero, physical, is reachable; [0, f] SI from a start
    at 0), value -/+ f |value| for a real one."""
    scale = abs(value) if value != 0 else 1.0
    if kind == "nonnegative" and linear:
        return 0.0, max(value, 0.0) + (factor - 1.0) * scale
    if kind != "real":
        return value / factor, value * factor
    return value - factor * scale, value + factor * scale


def output_matrix(model: Model, p: np.ndarray | None = None) -> np.ndarray:
    """C = dy/dx (n_y, n_x) of the model's output map at x = 0, u = 0 and parameters ``p``
    (SI, model order; default all 1): y = C x exactly where every output is a state (a
    coordinate, a rate: ``state_outputs``), the output map's linearization otherwise."""
    x = ca.SX.sym("x", model.n_states)
    u = ca.SX.sym("u", model.n_inputs)
    q = ca.SX.sym("p", len(model.parameters))
    c = ca.Function("c", [x, u, q], [ca.jacobian(model.output_map(x, u, q), x)])
    values = np.ones(len(model.parameters)) if p is None else p
    return np.array(c(np.zeros(model.n_states), np.zeros(model.n_inputs), values))


def rigid_modes(model: Model, p: np.ndarray) -> np.ndarray:
    """Basis (n_q, n_rigid) of coordinate motions that stretch no belt: null space of the
    stiffness matrix d^2 V / dq^2 (used to fill unmeasured coordinates from measured ones)."""
    x = ca.SX.sym("x", model.n_states)
    nq = model.n_states // 2
    _, potential = model.energy(x, p)
    hess, _ = ca.hessian(potential, x[:nq])
    k = np.array(ca.Function("k", [x], [hess])(np.zeros(model.n_states)))
    u, sing, vt = np.linalg.svd(k)
    rank = int(np.sum(sing > sing.max() * 1e-9))
    return vt[rank:].T


def rest_projector(model: Model, p: np.ndarray) -> np.ndarray:
    """(n_x, n_x) orthogonal projector onto the initial-state steps of a record at rest: no
    velocity, positions only along the rigid modes (``rigid_modes`` at ``p``), so the belts
    stay unstretched: the model's equilibrium under no input, and the state ``validate``
    starts such a record from (``fitting.rest_state.rest_state``). Estimating the stretches
    too let a fit start each record with belts pulled taut by up to 0.6 rad of motor angle,
    followed data from there that the written file, replayed from rest, missed by 20,000
    chi^2/2 units (issue 25, docs/studies/2026-11-26-rest-states.md). A model without
    springs keeps every position free."""
    nq = model.n_states // 2
    modes = rigid_modes(model, p)
    projector = np.zeros((model.n_states, model.n_states))
    rigid = np.eye(nq) if modes.shape[1] == nq else modes @ modes.T
    projector[:nq, :nq] = rigid
    return projector
