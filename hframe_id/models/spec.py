"""Named, unit-carrying descriptions of signals and parameters shared by all model variants."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

ParameterKind = Literal["positive", "nonnegative"]


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

    ``kind`` says which values are physical: ``"positive"`` (masses, stiffnesses, viscous
    friction, motor constants) or ``"nonnegative"`` (Coulomb friction, which is zero in the
    thesis's linear models). ``required=False`` marks parameters that only some model options
    use (belt lengths for position-dependent stiffness, section 4.6).
    """

    name: str
    unit: str
    description: str
    kind: ParameterKind = "positive"
    required: bool = True

    @property
    def key(self) -> str:
        """The key used in parameter files: name with unit, e.g. ``"k_l [N/m]"``."""
        return f"{self.name} [{self.unit}]"

    @property
    def is_coulomb(self) -> bool:
        """True for Coulomb friction levels (which linearization excludes)."""
        return self.kind == "nonnegative"
