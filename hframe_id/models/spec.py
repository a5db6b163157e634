"""Named, unit-carrying descriptions of signals and parameters shared by all model variants."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from hframe_id.errors import ModelError

ParameterKind = Literal["positive", "nonnegative", "real"]
PARAMETER_KINDS = ("positive", "nonnegative", "real")


@dataclass(frozen=True)
class Signal:
    """A named state, input or output with its SI unit."""

    name: str
    unit: str
    description: str

    @property
    def label(self) -> str:
        """Name with unit, as used in files, plots and reports, e.g. ``"x [m]"``."""
        return f"{self.name} [{self.unit}]"


@dataclass(frozen=True)
class ParameterSpec:
    """One physical parameter of a model variant.

    ``kind`` says which values are physical: ``"positive"`` (masses, stiffnesses, inertias,
    motor constants), ``"nonnegative"`` (friction, viscous and Coulomb: zero is physical,
    Coulomb friction is zero in the thesis's linear models) or ``"real"`` (either sign:
    offsets, biases). A fit estimates positive parameters in log scale, real ones linearly,
    and nonnegative ones in log scale until the data push one to its lower bound, then
    linearly down to zero (``hframe_id.fitting.problem``, ``FitOptions.zero_reachable``).
    ``required=False`` marks parameters that only some model options use (belt lengths for
    position-dependent stiffness, section 4.6).
    """

    name: str
    unit: str
    description: str
    kind: ParameterKind = "positive"
    required: bool = True

    def __post_init__(self) -> None:
        if self.kind not in PARAMETER_KINDS:
            raise ModelError(
                f"parameter {self.name!r}: kind {self.kind!r} is not one of "
                f"{', '.join(PARAMETER_KINDS)}"
            )

    @property
    def key(self) -> str:
        """The key used in parameter files: name with unit, e.g. ``"k_l [N/m]"``."""
        return f"{self.name} [{self.unit}]"
