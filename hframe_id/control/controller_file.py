"""Controllers declared in a Python file, without touching the package (docs/custom-models.md).

A controller file sets ``CONTROLLER = declare_controller(...)``, for instance a proportional
position loop::

    def law(y, r, z, g, T):
        return {"commands": {"v": g["k_p"] * (r["x_ref"] - y["x"])}}

    CONTROLLER = declare_controller(
        name="p-loop",
        description="proportional position loop",
        commands=[Signal("v", "V", "drive voltage")],
        measured=["x"],
        references=[Signal("x_ref", "m", "position reference")],
        gains=[Gain("k_p", 50.0, "V/m", "position gain")],
        law=law,
        limits={"v": (-10.0, 10.0)},
    )

or uses a built-in: ``CONTROLLER = pid_controller(...)`` (``hframe_id.control.pid``).
``y``, ``r``, ``z`` and ``g`` map the declared names to CasADi symbols (use ``casadi.fmin``,
``casadi.if_else``, ... on them); a name that was not declared is an error naming the file and
the name. ``models/emps_controller.py`` is a complete example.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path

from hframe_id.control.declaration import (
    CHECK_PERIOD_S,
    ControllerDeclaration,
    Gain,
    Law,
    SamplePeriod,
    traced_law,
)
from hframe_id.errors import ControllerError
from hframe_id.models.spec import Signal
from hframe_id.models.user import load_guarded, run_declaration_file


def declare_controller(
    name: str,
    description: str,
    commands: Sequence[Signal],
    law: Law,
    measured: Sequence[str] = (),
    references: Sequence[Signal] = (),
    states: Sequence[Signal] = (),
    gains: Sequence[Gain] = (),
    sample_period_s: SamplePeriod = None,
    delay_samples: int = 0,
    limits: Mapping[str, tuple[float, float]] | None = None,
    disturbances: Mapping[str, str] | None = None,
) -> ControllerDeclaration:
    """Declare a controller (fields: ``ControllerDeclaration``; an example: the module
    docstring). ``limits`` maps a command to its (lower, upper) saturation, ``disturbances``
    a command to the recording signal added to it after the saturation."""
    file = sys._getframe(1).f_globals.get("__file__")
    return ControllerDeclaration(
        name=name,
        description=description,
        commands=tuple(commands),
        measured=tuple(measured),
        references=tuple(references),
        states=tuple(states),
        gains=tuple(gains),
        law=law,
        sample_period_s=sample_period_s,
        delay_samples=delay_samples,
        limits=tuple((k, *v) for k, v in dict(limits or {}).items()),
        disturbances=tuple(dict(disturbances or {}).items()),
        source=str(Path(file).resolve()) if file else "<declare_controller>",
    )


def load_controller_file(path: str | Path) -> ControllerDeclaration:
    """Load a controller file and check it by tracing its law.

    Every problem, however the file's code ends (``hframe_id.models.user.load_guarded``), is
    a one-line ``ControllerError`` naming the file and the item.
    """
    return load_guarded(path, "controller file", ControllerError, _load_controller_file)


def _load_controller_file(path: Path) -> ControllerDeclaration:
    path, module = run_declaration_file(path, "controller file", ControllerError)
    declared = getattr(module, "CONTROLLER", None)
    if not isinstance(declared, ControllerDeclaration):
        raise ControllerError(
            f"controller file {path}: defines no CONTROLLER = declare_controller(...) "
            f"(found {type(declared).__name__})"
        )
    declared = replace(declared, source=str(path), controller_file=path)
    traced_law(declared, CHECK_PERIOD_S)
    return declared
