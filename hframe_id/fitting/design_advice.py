"""Experiment-design advice: which standard experiments would identify a parameter the
fitted data do not.

Called by ``fit_recordings`` for the parameters it held for identifiability; each candidate
of :func:`hframe_id.fitting.designs.standard_designs` not already in the data is simulated at
the fitted parameters (noise-free, through the rig's DAC and laser range), transcribed like
the data, and its Gauss-Newton information added to the data's (docs/fitting.md,
"Identifiability"); the prediction is ``hframe_id.design.information``'s, which
``hframe-id design`` optimises.
"""

from __future__ import annotations

import math

import numpy as np

from hframe_id.design.information import reduced_information
from hframe_id.errors import FitError
from hframe_id.fitting.designs import standard_designs
from hframe_id.fitting.options import FitOptions
from hframe_id.fitting.problem import FitProblem
from hframe_id.fitting.shooting import MultipleShooting
from hframe_id.fitting.solver import GaussNewton, SolverState
from hframe_id.fitting.statistics import Statistics


def identifying_designs(
    problem: FitProblem,
    ms: MultipleShooting,
    gn: GaussNewton,
    state: SolverState,
    stats: Statistics,
    not_identified: tuple[str, ...],
    threshold: float,
) -> dict[str, tuple[str, ...]]:
    """For each parameter the data do not identify, the standard experiments that would.

    The information of a candidate experiment is computed at the fitted parameters from
    noise-free simulated data, reduced to the parameters (its initial state eliminated), and
    added to the data's; the parameter counts as identified if its textbook relative error,
    scaled by the data's ratio of robust to textbook errors, is below the threshold.
    Candidates are transcribed like the data (``ms.transcription``).

    Parameters
    ----------
    problem, ms, gn, state, stats
        The fitted problem, its transcription, solver, final iterate and statistics.
    not_identified
        Free parameters held for identifiability (names).
    threshold
        The identifiability threshold (``FitOptions.identifiability_threshold``): the
        largest relative standard error of an identified parameter.

    Returns
    -------
    Per name in ``not_identified``: the names of the standard designs
    (:func:`hframe_id.fitting.designs.standard_designs`) of which each alone, added to the
    data, would identify it; else ``("all of A, B, ...",)`` if only all of them together
    would; else ``()``.
    """
    all_free = np.ones(len(problem.free), dtype=bool)
    jac, _, _ = gn.condensed_jacobian(state.evaluation, state.nodes, all_free)
    info_data = reduced_information(jac, ms.n_nuisance)
    ratio = 1.0
    if stats.relative_std_gn.size:
        with np.errstate(divide="ignore", invalid="ignore"):
            ratios = stats.relative_std / stats.relative_std_gn
        ratios = ratios[np.isfinite(ratios)]
        ratio = float(np.median(ratios)) if ratios.size else 1.0
    ratio *= stats.noise_scale
    fitted = problem.parameter_set(state.theta)
    present = {e.name.removesuffix(".mcap") for e in problem.experiments}
    candidates = []
    for design in standard_designs(problem.model.variant, problem.sample_period_s):
        if design.name in present:
            continue
        try:
            info = _design_information(problem, ms, design, fitted)
        except FitError:
            continue
        candidates.append((design.name, info))
    index = {n: problem.free_names.index(n) for n in not_identified}

    def identified_with(info: np.ndarray, name: str) -> bool:
        cov = np.linalg.pinv(info, hermitian=True)
        std = math.sqrt(max(cov[index[name], index[name]], 0.0)) * ratio
        return std <= threshold

    advice = {}
    for name in not_identified:
        single = tuple(n for n, info in candidates if identified_with(info_data + info, name))
        if not single and candidates:
            total = info_data + sum(info for _, info in candidates)
            single = (
                ("all of " + ", ".join(n for n, _ in candidates),)
                if identified_with(total, name)
                else ()
            )
        advice[name] = single
    return advice


def _design_information(problem: FitProblem, ms: MultipleShooting, design, fitted):
    """Reduced information about the free log-parameters of one candidate experiment, on
    the data's rig (``hframe_id.design.information``) at the ``fitted`` parameter set, in
    windows and threads of the data's transcription ``ms``."""
    from hframe_id.design.information import experiment_information

    rec0 = problem.experiments[0].recording
    options = FitOptions(
        free=problem.free_names,
        channel_std=dict(zip(problem.output_names, problem.channel_std.tolist(), strict=True)),
        shooting_interval=ms.transcription.shooting_interval,
        smoothing=problem.smoothing,
        threads=ms.transcription.threads,
    )
    info = experiment_information(
        fitted,
        [design.inputs],
        options,
        sample_period_s=problem.sample_period_s,
        rig=rec0.rig,
        names=[design.name],
    )
    return info.matrix
