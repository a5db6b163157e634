"""Where the local fit starts: the best point the fit knows, by the criterion of its file.

The output-error stages are local: they end in the basin they start in. A start chosen by a
criterion of its own (the equation-error regression's residuals, or the output error of
independent shooting windows) can lie in a poor basin although a point the fit knows
simulates the data far better: on the lubricated plant of issue 25 the regression from one
seeded start won the windowed test (3 x lower) and lost the free run (concentrated
criterion -12,705 against the start's -30,648 and Table 4.1's -53,921); the fit from it
ended with M_bridge at 641 kg and 4.6 rad of motor-angle error.

So every point the fit knows (``known_points.candidate_thetas``: the start, the
equation-error estimate, the model's reference files, the user's known points), clipped
into the fit's box, is judged by the criterion that judges the written file
(``known_points.simulation_criterion``: a free run of every training record from rest, or
from its measured first node where it starts in motion), concentrated over the channels'
noise levels floored at the sensors' std (the levels are not known before the fit), and the
fit starts from the best. The same points are judged again, by the fit's own criterion,
once it ends (``fit._never_worse_than_known``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hframe_id.fitting.known_points import simulation_criterion
from hframe_id.fitting.problem import FitProblem
from hframe_id.recordings.recording import Recording


@dataclass(frozen=True)
class ScreenedStart:
    """The start the local fit takes: ``theta`` (``FitProblem.parameters``), its ``label``,
    and every candidate's criterion (label -> concentrated criterion, inf where its
    simulation fails)."""

    theta: np.ndarray
    label: str
    criteria: dict[str, float]

    def statement(self) -> str:
        """Which point the fit starts from, and every candidate's criterion."""
        values = ", ".join(f"{label} {value:.6g}" for label, value in self.criteria.items())
        return (
            f"the fit starts from {self.label}, the best point it knows by the concentrated "
            f"free-run criterion ({values})"
        )


def screened_start(
    problem: FitProblem,
    recordings: Sequence[Recording],
    candidates: Sequence[tuple[str, np.ndarray]],
    first_nodes: np.ndarray,
) -> ScreenedStart:
    """The best of ``candidates`` ((label, theta) pairs, the first the start itself) by the
    concentrated free-run criterion, each clipped into the problem's box; ``first_nodes``
    (experiments, n_x): the measured first states, used for records that start in motion.
    Ties keep the earlier candidate (the start first)."""
    std = dict(zip(problem.output_names, problem.channel_std.tolist(), strict=True))
    starts = [
        None if experiment.at_rest else first_nodes[e]
        for e, experiment in enumerate(problem.experiments)
    ]
    criteria: dict[str, float] = {}
    best = None
    seen = set()
    for label, theta in candidates:
        clipped = np.clip(theta, problem.theta_lower, problem.theta_upper)
        if clipped.tobytes() in seen:  # a reference file equal to the start, in the box
            continue
        seen.add(clipped.tobytes())
        value = simulation_criterion(
            problem.initial.replace_values(**_free_values(problem, clipped)),
            recordings,
            std,
            dict(problem.options.latency_samples),
            starts,
            concentrated=True,
        )
        criteria[label] = value
        if best is None or value < best[2]:
            best = (clipped, label, value)
    theta, label, _ = best
    return ScreenedStart(theta, label, criteria)


def _free_values(problem: FitProblem, theta: np.ndarray) -> dict[str, float]:
    """The free parameters' values [SI] at ``theta``."""
    p = problem.parameters(theta)
    return {name: float(p[i]) for i, name in zip(problem.free, problem.free_names, strict=True)}
