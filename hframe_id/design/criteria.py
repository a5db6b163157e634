"""Design criteria: one number per information matrix, smaller is better.

F is the Fisher information about the free parameters theta (relative changes,
``hframe_id.design.information``), C = F^-1 their covariance (white noise):

- ``"D"``: -ln det F / n, the mean log of the inverse variances along the principal axes
  (D-optimal: the smallest joint confidence ellipsoid; invariant to rescaling parameters);
- ``"A"``: ln trace C, the log of the summed relative variances;
- ``"E"``: -ln lambda_min(F), the worst-determined direction;
- ``"focus"``: ln sum_{i in focus} C_ii, the summed relative variances of the named
  parameters only (the others estimated alongside them; A-optimality on a subset).

Logs keep the criteria comparable between parameter sets (``optimise`` averages them over
parameter draws) whatever the size of the information.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hframe_id.errors import OptionError

CRITERIA = ("D", "A", "E")


@dataclass(frozen=True)
class Criterion:
    """A design criterion: ``kind`` (one of ``CRITERIA``), or a ``focus`` on named free
    parameters (then ``kind`` is ``"focus"``)."""

    kind: str = "D"
    focus: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.focus and self.kind != "focus":
            object.__setattr__(self, "kind", "focus")
        if self.kind not in (*CRITERIA, "focus"):
            raise OptionError(
                f"--criterion must be one of {', '.join(CRITERIA)}, got {self.kind!r}"
            )
        if self.kind == "focus" and not self.focus:
            raise OptionError("a focus criterion needs at least one parameter name")

    def describe(self) -> str:
        """``D-optimal`` or ``focus on F_c_cart, F_c_bridge``."""
        return f"focus on {', '.join(self.focus)}" if self.focus else f"{self.kind}-optimal"

    def indices(self, names: Sequence[str]) -> np.ndarray:
        """Positions of the focus parameters among the free ``names``; ``OptionError`` for a
        name that is not free (suggesting the nearest)."""
        index = []
        for name in self.focus:
            if name not in names:
                close = difflib.get_close_matches(name, list(names), n=1, cutoff=0.5)
                hint = f" (did you mean {close[0]!r}?)" if close else ""
                raise OptionError(
                    f"--focus {name!r} is not a free parameter{hint}; free: {', '.join(names)}"
                )
            index.append(list(names).index(name))
        return np.array(index, dtype=int)

    def value(self, info: np.ndarray, focus_index: np.ndarray | None = None) -> float:
        """The criterion of information ``info`` (n_f, n_f) (smaller is better; inf for a
        singular one). ``focus_index``: ``indices`` of the free names, for ``"focus"``."""
        n = info.shape[0]
        if self.kind == "D":
            sign, logdet = np.linalg.slogdet(info)
            return -logdet / n if sign > 0 else math.inf
        if self.kind == "E":
            smallest = float(np.linalg.eigvalsh(info)[0])
            return -math.log(smallest) if smallest > 0 else math.inf
        try:
            cov = np.linalg.inv(info)
        except np.linalg.LinAlgError:
            return math.inf
        picked = np.diag(cov) if self.kind == "A" else np.diag(cov)[focus_index]
        total = float(np.sum(picked))
        return math.log(total) if total > 0 and math.isfinite(total) else math.inf
