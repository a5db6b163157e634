"""Consider covariance: what the uncertainty of held parameters does to the fitted ones.

A parameter held at a table value is not known exactly; its error moves the free estimates.
Linearised at the optimum, with J = [J_a, J_c] the weighted-residual Jacobian split into the
estimated columns a (initial states and free log-parameters) and the held ("considered")
log-parameters c, a change dc of the held values moves the estimate by

    da = S dc,   S = -(J_a^T J_a)^-1 J_a^T J_c

so a prior covariance P_c of the held log-parameters (relative std sigma_c: P_c = diag
sigma_c^2) adds S P_c S^T to the covariance of the free ones (the "consider covariance" of
orbit determination; Tapley, Schutz & Born, Statistical Orbit Determination, sec. 6.3).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Consider:
    """What a fit's intervals assume about the parameters it held
    (``held_uncertainty.include_held_uncertainty``).

    ``held_relative_std``: each held parameter with a prior, by name, its prior relative std
    (dimensionless, 0.2: +/-20 %); ``method``: how the priors entered the intervals,
    ``"linear"`` (the consider covariance at the optimum) or ``"refit"`` (whole refits);
    ``relative_std_added``: per free parameter, the std the priors add, in its theta units
    (relative for log-scale parameters; SI over the parameter's linear scale for signed
    ones); ``failed_refits``: the refits that did not converge (``"name xfactor:
    message"``).
    """

    held_relative_std: dict[str, float]
    method: str = "linear"
    relative_std_added: dict[str, float] = field(default_factory=dict)
    failed_refits: tuple[str, ...] = ()


def consider_covariance(
    jac_estimated: np.ndarray, jac_held: np.ndarray, held_relative_std: np.ndarray
) -> np.ndarray:
    """Covariance added to the estimated columns by the held parameters' prior uncertainty.

    Parameters
    ----------
    jac_estimated : (n, n_a) Jacobian of the weighted residuals in the estimated columns.
    jac_held : (n, n_c) the same in the held log-parameters.
    held_relative_std : (n_c,) prior relative std of each held parameter (0.2: +/-20 %).

    Returns
    -------
    (n_a, n_a) covariance S diag(sigma_c^2) S^T, in the estimated columns' units (log p for
    parameters).
    """
    info = jac_estimated.T @ jac_estimated
    scale = np.sqrt(np.maximum(np.diag(info), 1e-300))
    inv = np.linalg.pinv(info / np.outer(scale, scale), rcond=1e-13, hermitian=True)
    inv /= np.outer(scale, scale)
    sensitivity = -inv @ (jac_estimated.T @ jac_held)
    return (sensitivity * np.asarray(held_relative_std) ** 2) @ sensitivity.T
