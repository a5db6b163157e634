"""The tuning of the condensed Gauss-Newton iteration (``fitting.solver``), as one option.

``FitOptions(gauss_newton=GaussNewtonSettings(...))`` (or ``SolverOptions``) hands them to
every Gauss-Newton stage of a fit; the defaults are the values the project's fits, tests and
studies were measured with (docs/fitting.md, "The stages"). Units: the trust region is a
2-norm on the free log-parameters (or the parameters themselves, for those fitted linearly
from zero); costs are chi^2 / 2 (residuals in noise std); defects are in noise std.
"""

from __future__ import annotations

from dataclasses import dataclass

from hframe_id.errors import OptionError, shown
from hframe_id.fitting.option_checks import check_numbers

#: Fields that are whole numbers (counts of iterations or returns).
_COUNTS = ("watchdog_patience", "watchdog_reverts", "free_steps", "cost_window")
#: Fields that are shares in (0, 1).
_FRACTIONS = ("give_up_decrease", "merit_rho")
#: (smaller, larger) pairs that must stay ordered.
_ORDERED = (
    ("min_radius", "max_radius"),
    ("min_radius", "watchdog_min_radius"),
    ("node_damping", "max_node_damping"),
    ("min_prox_scale", "max_prox_scale"),
)


@dataclass(frozen=True)
class GaussNewtonSettings:
    """How the Gauss-Newton iteration globalises its steps and when it stops.

    Attributes
    ----------
    max_radius, min_radius : the trust region's largest radius, and the smallest before a
        stage gives up (no step is accepted): 4 (a factor e^4 ~ 55 on a parameter in one
        step) and 1e-9.
    node_damping, max_node_damping : the Marquardt damping of the node blocks, relative to
        their diagonal, at the start of a stage (keeps the solve regular where a window's
        data do not determine its node state, e.g. speed at rest) and the largest it is
        raised to while steps are refused.
    proximal_weight : weight of node velocity steps: a step of one smoothing velocity costs
        this many noise-sized residuals (``CondensedModel.set_smoothing``).
    min_prox_scale, max_prox_scale : the proximal weight adapts like a Levenberg-Marquardt
        damping within these factors of ``proximal_weight``.
    watchdog_factor : an exact stage (l1 merit) accepts a step whose merit is below this
        many times the best merit so far; the watchdog returns to the best iterate after
        ``watchdog_patience`` steps without a new best, with the region at least
        ``watchdog_min_radius``, and after ``watchdog_reverts`` returns the stage goes on as
        a monotone trust-region method (so it cannot cycle).
    close_cost_tol : a stalled exact stage whose nodes, simulated from the initial states,
        cost at most this much more than the lifted iterate [chi^2 / 2] is converged: 1 is
        below the 1.92 of a 95 % likelihood-ratio test on one parameter.
    stall_defect_tol : a stall with every continuity defect below this [noise std] is
        accepted as converged, provided the residual rms is at most ``stall_noise_ratio``
        noise std (a stall far from the data is a failure, whatever the defects).
    free_steps : an exact stage accepts its first steps unconditionally: they close the
        defects left by the previous stage, which raises the cost before it falls.
    give_up_decrease, give_up_noise_ratio : a fast path (a stage run with ``give_up``)
        stops when its best merit has not fallen by this share over ``give_up`` iterations
        while the residual rms is above ``give_up_noise_ratio`` noise std.
    cost_window : iterations over which an exact stage run with ``cost_rtol`` judges the
        cost decrease (a crawl of tiny steps along a valley lowers it a little every time).
    merit_rho : share of the removed l1 penalty a full exact-stage step must predict as a
        merit decrease (Nocedal & Wright, eq. 18.36), which sets the penalty parameter.
    sloppy_std : where parameters that the data do not determine are held still
        (``freeze_sloppy``), the textbook relative std of log p above which a parameter is
        not moved in an iteration.
    """

    max_radius: float = 4.0
    min_radius: float = 1e-9
    node_damping: float = 1e-6
    max_node_damping: float = 1e8
    proximal_weight: float = 1.0
    min_prox_scale: float = 1e-3
    max_prox_scale: float = 1e4
    watchdog_factor: float = 10.0
    watchdog_patience: int = 4
    watchdog_min_radius: float = 1e-2
    watchdog_reverts: int = 2
    close_cost_tol: float = 1.0
    stall_defect_tol: float = 2.0
    stall_noise_ratio: float = 1.5
    free_steps: int = 2
    give_up_decrease: float = 0.2
    give_up_noise_ratio: float = 10.0
    cost_window: int = 10
    merit_rho: float = 0.1
    sloppy_std: float = 0.5

    def __post_init__(self) -> None:
        check_numbers(self, "gauss_newton", counts=_COUNTS, fractions=_FRACTIONS)
        for low, high in _ORDERED:
            if getattr(self, low) > getattr(self, high):
                raise OptionError(
                    f"gauss_newton.{low} must not exceed gauss_newton.{high}, got "
                    f"{shown(getattr(self, low))} > {shown(getattr(self, high))}"
                )
