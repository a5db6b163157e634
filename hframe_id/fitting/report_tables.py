"""The fit report's sections computed from the fit alone, as markdown lines: the parameter table
against the reference set (and truth), the parameters the data do not identify, the groups of
strongly correlated parameters and the leave-one-recording-out section with its jackknife
sentence. No simulation, no figures, no files: :mod:`hframe_id.fitting.report` assembles them.
"""

from __future__ import annotations

import numpy as np

from hframe_id.fitting.result import FitResult
from hframe_id.parameters import ParameterSet
from hframe_id.validation.cross_validation import LeaveOneOutTable


def _fmt(value: float) -> str:
    return f"{value:.5g}"


def _relative_difference(value: float, reference: float, digits: int) -> str:
    """``value`` against ``reference`` in percent, or the absolute difference where the
    reference is 0 (a linear table's Coulomb friction), which has no relative one."""
    if reference == 0:
        return f"{_fmt(value - reference)} (reference 0)"
    return f"{100 * (value / reference - 1):+.{digits}f} %"


def markdown_table(rows: list[tuple[str, ...]]) -> list[str]:
    """Markdown lines of a table whose first row is the header."""
    head, *body = rows
    return [
        "| " + " | ".join(head) + " |",
        "|" + " --- |" * len(head),
        *("| " + " | ".join(row) + " |" for row in body),
    ]


def parameter_table(
    result: FitResult,
    thesis: ParameterSet | None,
    label: str,
    truth: ParameterSet | None,
    truth_label: str = "truth",
) -> list[str]:
    """Markdown rows of the free parameters: reference value (``thesis``, labelled
    ``label``), fitted value, interval, the experiment-level jackknife's interval (after a
    cross-validation), difference from the reference [%], identifiability and, with
    ``truth``, the error against it [%] ("n/a" where the truth's model lacks the parameter,
    as a section-4.1 reduction lacks I_max); units in the parameter names."""
    header = (
        "parameter",
        f"reference ({label})",
        "fitted",
        "95 % interval",
        "vs reference",
        "status",
    )
    jackknife = result.has_jackknife
    if jackknife:
        header = header[:4] + ("95 % interval, experiments (jackknife)",) + header[4:]
    if truth:
        header += (truth_label, "error vs truth")
    rows = [header]
    for est in result.estimates.values():
        if not est.free:
            continue
        ref = thesis.values.get(est.name) if thesis else None
        diff = _relative_difference(est.estimate, ref, 2) if ref is not None else "n/a"
        status = result.status_of(est.name)
        cells = (
            est.key,
            _fmt(ref) if ref is not None else "n/a",
            _fmt(est.estimate),
            f"[{_fmt(est.ci95[0])}, {_fmt(est.ci95[1])}]",
            diff,
            status,
        )
        if jackknife:
            ci = est.jackknife_ci95
            cells = cells[:4] + (f"[{_fmt(ci[0])}, {_fmt(ci[1])}]" if ci else "n/a",) + cells[4:]
        if truth:
            t = truth.values.get(est.name)  # None: a parameter the truth's model lacks
            cells += (
                ("n/a", "n/a") if t is None else (_fmt(t), _relative_difference(est.estimate, t, 3))
            )
        rows.append(cells)
    return markdown_table(rows)


#: |correlation| from which the report calls two free parameters strongly correlated: their
#: estimates move together, and the data fix a combination better than each one.
STRONG_CORRELATION = 0.9


def correlated_groups(result: FitResult) -> list[tuple[tuple[str, ...], float]]:
    """Groups of free parameters joined by |correlation| >= STRONG_CORRELATION (connected
    components), each with its largest |correlation|, strongest first."""
    names = list(result.free_names)
    strong = np.abs(np.asarray(result.correlation)) >= STRONG_CORRELATION
    seen: set[int] = set()
    groups = []
    for start in range(len(names)):
        if start in seen:
            continue
        members, todo = [], [start]
        while todo:
            k = todo.pop()
            if k in seen:
                continue
            seen.add(k)
            members.append(k)
            todo += [j for j in np.flatnonzero(strong[k]) if j not in seen]
        if len(members) > 1:
            members.sort()
            block = np.abs(np.asarray(result.correlation)[np.ix_(members, members)])
            largest = float(np.max(block - np.eye(len(members))))
            groups.append((tuple(names[k] for k in members), largest))
    return sorted(groups, key=lambda group: -group[1])


def correlation_lines(result: FitResult) -> list[str]:
    """What the data cannot separate: a line per strongly correlated group, with the
    experiments that would separate it where the fitter's design advice names any."""
    groups = correlated_groups(result)
    if not groups:
        return [f"No two free parameters have |r| >= {STRONG_CORRELATION}."]
    lines = [
        f"Strongly correlated free parameters (|r| >= {STRONG_CORRELATION}): within each group, "
        "these data determine a combination of the parameters much better than each one. "
        "The intervals above include this; change one only together with the others (the "
        "parameter file's uncertainty section holds the correlation matrix).",
        "",
    ]
    advised = False
    for group, largest in groups:
        keys = ", ".join(result.estimates[name].key for name in group)
        advice = sorted({d for name in group for d in result.estimates[name].identified_by})
        advised |= bool(advice)
        tail = f"; experiments that would separate them: {', '.join(advice)}" if advice else ""
        lines.append(f"- {keys} (|r| up to {largest:.3f}){tail}")
    if not advised:
        lines += [
            "",
            "To separate a group, add an experiment that excites its members differently "
            "(another amplitude, direction or frequency content); the fitter proposes standard "
            "experiments only for parameters it cannot identify.",
        ]
    return lines


def not_identified_lines(result: FitResult) -> list[str]:
    """Free parameters the data do not determine: held at their initial values, stopped by
    a bound of the box, or (under model mismatch) kept at their estimates."""
    weak = [est for est in result.estimates.values() if est.free and not est.identified]
    if not result.success or not weak:
        return []
    lines = ["## Not identified, at a bound or poorly determined", ""]
    for est in weak:
        if est.open_ended:
            fate = (
                f"on the box at {_fmt(est.estimate)}, and the data do not bound it "
                f"{est.open_ended}: moved back towards the start, the fit is no worse "
                "(see the verdict); any value beyond its interval's finite end fits as well."
            )
        elif est.at_bound:
            fate = (
                f"stopped at a bound of the box, {_fmt(est.estimate)}: the data push it "
                "further, the box fixes it (--bounds widens the box)."
            )
        elif est.name in result.not_identified:
            would = (
                ", ".join(est.identified_by)
                if est.identified_by
                else "none of the standard step experiments alone"
            )
            fate = (
                f"held at its initial value {_fmt(est.initial)}. Experiments that would "
                f"identify it: {would}."
            )
        else:
            fate = f"kept at its estimate {_fmt(est.estimate)} (poorly determined)."
        lines.append(
            f"- {est.key}: relative standard error {100 * est.relative_std:.3g} % "
            f"(collinearity {est.collinearity:.3g}); {fate}"
        )
    return [*lines, ""]


def cross_validation_lines(result: FitResult, table: LeaveOneOutTable) -> list[str]:
    return [
        "## Leave-one-recording-out cross-validation",
        "",
        "Each recording simulated with the parameters fitted to the others (same options and "
        "start): simulation fit [%] = 100 (1 - |y - y_hat| / |y - mean(y)|) per channel, and "
        "the free parameters' spread across the converged folds (SI), with the "
        "experiment-level jackknife standard error.",
        "",
        table.markdown(),
        "",
        *jackknife_sentence(result, table),
    ]


#: Jackknife std over the fit's std error above which the report says the intervals are
#: too narrow: 2 (a ratio of two noisy standard errors, with few experiments, scatters by
#: tens of percent even when both estimate the same spread).
JACKKNIFE_RATIO = 2.0


def jackknife_sentence(result: FitResult, table: LeaveOneOutTable) -> list[str]:
    """Which parameters move across experiments by more than their intervals allow."""
    wider = []
    for s in table.spread:
        est = result.estimates.get(s.name)
        if est and est.std_error > 0 and s.jackknife_std > JACKKNIFE_RATIO * est.std_error:
            wider.append(f"{s.name} ({s.jackknife_std / est.std_error:.3g}x)")
    if not wider:
        return []
    return [
        "The fit's intervals account for noise only. Across experiments, these parameters "
        "move by more than twice their standard error (jackknife std / fit std): "
        f"{', '.join(wider)}. Model error that differs between experiments is larger than the "
        "intervals say; read the jackknife interval of the parameter table as theirs.",
        "",
    ]


def information_lines(result: FitResult) -> list[str]:
    """Which recordings carry each free parameter's information (``Statistics
    .information_share``, in %): a parameter that only one recording determines depends on
    that experiment; one that none determines needs another (``hframe-id design``)."""
    shares = result.statistics.information_share if result.statistics else {}
    if not shares or len(result.experiment_names) < 2:
        return []
    recordings = list(next(iter(shares.values())))
    rows = [("parameter", *recordings)]
    for name, share in shares.items():
        rows.append((result.estimates[name].key, *(f"{100 * share[r]:.0f} %" for r in recordings)))
    return [
        "## Where each parameter's information comes from",
        "",
        "Share of each free parameter's Gauss-Newton information (its diagonal of J^T J) that "
        "each recording carries; marginal, correlations with the other parameters not removed.",
        "",
        *markdown_table(rows),
        "",
    ]
