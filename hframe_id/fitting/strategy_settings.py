"""The tuning of the fit's stages (``fitting.local_fit`` and the links it runs), as one option.

``FitOptions(strategy=StrategySettings(...))`` hands them to the stages: the intermediate
stages' tolerances, the state-estimation pre-pass, the fast path's patience, the noise
rounds, the box widenings, the restarts along unmeasured springs and the identifiability
holds. The defaults are the values the project's fits, tests and studies were measured
with; each field says why it has its value (docs/fitting.md has the measurements). Units:
costs chi^2 / 2 (residuals in noise std), defects and misfits in noise std.
"""

from __future__ import annotations

from dataclasses import dataclass

from hframe_id.errors import OptionError, shown
from hframe_id.fitting.option_checks import as_tuple, check_numbers, positive

#: Fields that are whole numbers.
_COUNTS = (
    "prepass_iterations",
    "fast_path_patience",
    "max_noise_rounds",
    "box_widenings",
    "restart_limit",
)
#: Fields that may be 0 (a count of nothing, or a tolerance every change exceeds).
_MAY_BE_ZERO = ("noise_rtol", "box_widenings", "restart_limit")


@dataclass(frozen=True)
class StrategySettings:
    """How the stages hand over to each other, and when each stops.

    Attributes
    ----------
    penalty_weight : weight of the continuity defects [noise std] in the penalty stages
        (the fallback that takes a poor start into the basin of the exact iteration, and
        the state-estimation pre-pass): one defect of one noise std costs as much as one
        residual of one noise std.
    penalty_cost_rtol : a penalty stage stops once an iteration lowers its cost by less
        than this (relative): it only has to reach the exact stage's basin.
    intermediate_step_tol, intermediate_defect_tol : the step [relative] and defect [noise
        std] tolerances of the stages before the last (the last uses ``FitOptions.step_tol``
        and ``defect_tol``): they only need to bring the iterate into the next one's basin.
    prepass_iterations, prepass_cost_rtol : the state-estimation pre-pass (nodes only,
        parameters held) runs at most this many iterations, and stops earlier once one lowers
        its merit by less than ``prepass_cost_rtol`` (relative).
    fast_path_patience : iterations without progress after which the fast path (exact
        continuity on the moving windows straight from the start) hands over to the penalty
        fallback (``GaussNewtonSettings.give_up_decrease``).
    mismatch_rms : a sensor-weighted fit whose residual rms exceeds this many sensor std
        does not fit at the noise level (matched sim-rig fits end at 1.0-1.3): with
        ``FitOptions.noise`` "auto" its levels are estimated, and a fit that ends above it
        on a channel states model mismatch.
    noise_rtol : the noise levels count as settled once no channel's std moves by more than
        this (relative, in log) over a round: 5 % of a std is a 10 % change of a channel's
        weight, below what moves an estimate by a standard error (0: every round runs).
    max_noise_rounds : rounds at most (settling is slow where a level first overshoots:
        seven rounds measured on two realistic steps with six parameters free).
    warm_cost_rtol : a warm-started noise round also stops once an iteration lowers the
        cost by less than this (relative): ~0.01 chi^2 / 2 at its costs (~N / 2 ~ 1e4),
        1 % of the statistical resolution.
    box_widenings : times the default box of a fit that ends on it is widened (bound factor
        squared: 10, 100, 1e4 by default), besides friction opened to zero once; still on it
        after that, the fit fails saying so. Four decades either side of the start hold the
        envelope of masses and stiffnesses within 0.4-2.5 x.
    restart_factors, restart_limit, restart_min_gain : restarts along the stiffnesses at an
        unmeasured coordinate: each moved by x/÷ each factor (> 1), at most ``restart_limit``
        solves, a restart kept when it is a better fit by a log-likelihood ratio above
        ``restart_min_gain`` (2: a likelihood ratio of e^2; ``resolution.likelihood_gain``).
    hold_misfit : an unconverged fit whose residual rms is above this many noise std is not
        worth holding parameters for identifiability (its error estimates mean nothing).
    hopeless_std : parameters whose relative standard error is above this are held together
        with the worst one, not one at a time.
    """

    penalty_weight: float = 1.0
    penalty_cost_rtol: float = 1e-3
    intermediate_step_tol: float = 1e-4
    intermediate_defect_tol: float = 1.0
    prepass_iterations: int = 30
    prepass_cost_rtol: float = 1e-4
    fast_path_patience: int = 6
    mismatch_rms: float = 3.0
    noise_rtol: float = 0.05
    max_noise_rounds: int = 10
    warm_cost_rtol: float = 1e-6
    box_widenings: int = 2
    restart_factors: tuple[float, ...] = (1.18, 1.4)
    restart_limit: int = 16
    restart_min_gain: float = 2.0
    hold_misfit: float = 1.5
    hopeless_std: float = 1.0

    def __post_init__(self) -> None:
        check_numbers(
            self, "strategy", counts=_COUNTS, may_be_zero=_MAY_BE_ZERO, skip=("restart_factors",)
        )
        self._check_restart_factors("strategy.restart_factors", self.restart_factors)

    def _check_restart_factors(self, name: str, value) -> None:
        """``restart_factors``: at least one number > 1, stored as a tuple of floats."""
        factors = None if isinstance(value, str) else as_tuple(value)
        if not factors:
            raise OptionError(f"{name} must be a sequence of factors > 1, got {shown(value)}")
        for factor in factors:
            positive(name, factor)
            if factor <= 1:
                raise OptionError(f"{name} must be factors > 1, got {shown(value)}")
        object.__setattr__(self, "restart_factors", tuple(float(f) for f in factors))
