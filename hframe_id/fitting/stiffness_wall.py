"""The stiffness wall as a constraint of the Gauss-Newton step.

A point whose friction at rest is so stiff that a stable RK4 integration needs more than
``max_substeps`` substeps per sample is refused (``MultipleShooting.evaluate``): the
integrator's domain ends there. Refused trials alone only shrink the trust region, so a fit
whose descent points beyond that wall walks into it with ever shorter steps and stops
against it, its answer decided by ``max_substeps`` (J_M1 1.84e-6 kg m^2 at 500, 4.59e-6 at
200, Table 4.2's 1.12e-4: docs/studies/2026-11-27-seeded-starts-and-the-stiffness-wall.md).

Here the wall is what a bound is to the box: a constraint the step respects. Once a trial
from a point is refused, the wall is linearised there in the log of the spectral radius at
rest, rho (the quantity that sets the substeps, ``substeps_for_radius``):

    log rho(theta + d) ~ log rho(theta) + n . d <= log rho_wall,
    rho_wall = (max_substeps - 1/2) * 2.785 / dt  [1/s]

(half a substep inside the wall, where the stability count, an integer, is not decided by
rounding)
and the step is the Gauss-Newton step within the trust region on that half-space: where the
unconstrained step crosses it, the minimiser on the hyperplane n . d = log rho_wall -
log rho(theta) (one linear equality eliminated, ``trust_region.step_on_hyperplane``),
on the parameters the step moves (``trust_region.bounded_step``: a parameter held at a
bound or frozen as sloppy does not push the step off the wall). The iterate then slides
along the wall while the data pull it there, and leaves it when they pull it back.

A fit that ends there has had its answer decided by ``max_substeps``, as a fit ending on a
default bound has by the box. ``wall_parameters`` names the free parameters that put it
there: those that set the Coulomb rate at rest of a coordinate stiff enough on its own that
the substep count is capped rather than set by the safety margin
(``substeps_for_radius``); the strategy restarts them (``fit._off_the_wall``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hframe_id.fitting.substep_plan import coulomb_rates, rest_and_moving_jacobians
from hframe_id.models import Model
from hframe_id.simulation.integrators import RK4_STABILITY_LIMIT, spectral_radius_at_rest

#: Forward-difference step in theta for n: sqrt(machine epsilon), the step that balances
#: truncation against rounding for a function of O(1) arguments computed to full precision
#: (the eigenvalues of df/dx at rest are).
DIFFERENCE_STEP = math.sqrt(np.finfo(float).eps)
#: An elasticity d log(rate) / d log(p) below this is rounding, not dependence: the forward
#: difference's rounding error is about DIFFERENCE_STEP, and a parameter the rate depends
#: on moves it in proportion (the Coulomb rate tau_c / (v_s J): elasticities +1 and -1).
DEPENDENCE = math.sqrt(DIFFERENCE_STEP)


@dataclass(frozen=True)
class StiffnessWall:
    """The wall linearised at one point: ``normal`` (n_free,) d log rho / d theta over the
    step's free parameters, ``margin`` log rho_wall - log rho at the point (> 0 at any point
    that was integrated)."""

    normal: np.ndarray
    margin: float

    @classmethod
    def at(cls, ms, theta: np.ndarray, index: np.ndarray, smoothing) -> StiffnessWall:
        """The wall of ``ms`` (``MultipleShooting``: its model, sample period and
        ``max_substeps``) linearised at ``theta`` over the free parameters ``index``."""
        problem = ms.problem

        def log_radius(th: np.ndarray) -> float:
            p = problem.parameters(th)
            return math.log(spectral_radius_at_rest(ms.model, p, smoothing))

        here = log_radius(theta)
        normal = np.empty(len(index))
        for k, i in enumerate(index):
            moved = theta.copy()
            moved[i] += DIFFERENCE_STEP
            normal[k] = (log_radius(moved) - here) / DIFFERENCE_STEP
        # Half a substep inside the wall: the count is an integer (ceil), so a step aimed at
        # the wall itself is refused or not by the rounding of its last digits.
        cap = ms.transcription.max_substeps - 0.5
        return cls(normal=normal, margin=math.log(cap * RK4_STABILITY_LIMIT / ms.dt) - here)


def _coulomb_rates(model: Model, p: np.ndarray, smoothing) -> np.ndarray:
    """(n_q,) ``substep_plan.coulomb_rates`` at all parameters ``p`` (SI, model order)."""
    a_rest, a_moving, _ = rest_and_moving_jacobians(model, p, smoothing)
    return coulomb_rates(a_rest, a_moving)


def wall_parameters(
    model: Model, p: np.ndarray, free_names, smoothing, dt: float, transcription
) -> tuple[str, ...]:
    """The free parameters (of ``free_names``) that set the Coulomb rate at rest of a
    coordinate whose rate alone caps the RK4 substeps at all parameters ``p`` (SI, model
    order): rate * dt * safety / 2.785 > max_substeps (``transcription``), so that
    ``max_substeps``, not the safety margin, sets the count. Empty where no coordinate is
    that stiff. A parameter sets a rate when the rate's elasticity to it exceeds
    ``DEPENDENCE``."""
    limit = transcription.max_substeps * RK4_STABILITY_LIMIT / (dt * transcription.substep_safety)
    rates = _coulomb_rates(model, p, smoothing)
    capped = rates > limit
    if not capped.any():
        return ()
    names = [spec.name for spec in model.parameters]
    out = []
    for name in free_names:
        i = names.index(name)
        if p[i] == 0.0:
            continue
        moved = p.copy()
        moved[i] *= 1.0 + DIFFERENCE_STEP
        ratio = _coulomb_rates(model, moved, smoothing)[capped] / rates[capped]
        if np.any(np.abs(np.log(ratio)) > DEPENDENCE * DIFFERENCE_STEP):
            out.append(name)
    return tuple(out)


def at_the_wall(problem, p: np.ndarray, options, dt: float) -> tuple[str, ...]:
    """``wall_parameters`` of a fit's ``problem`` (``FitProblem``: its model and free
    parameters) at all parameters ``p`` (SI, model order) under its ``options``
    (``FitOptions``: smoothing, transcription) and sample period ``dt`` [s]."""
    smoothing = options.smoothing or problem.model.options.smoothing
    return wall_parameters(
        problem.model, p, problem.free_names, smoothing, dt, options.transcription_options
    )
