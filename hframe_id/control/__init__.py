"""Closed-loop control: the H-frame's Chapter 5 (trajectories, reset-windup PID, metrics) and
declared controllers run on any model (``declare_controller``, docs/custom-models.md)."""

from hframe_id.control.controller_file import declare_controller, load_controller_file
from hframe_id.control.declaration import ControllerDeclaration, Gain
from hframe_id.control.pid import PIDGains, pid_controller

__all__ = [
    "ControllerDeclaration",
    "Gain",
    "PIDGains",
    "declare_controller",
    "load_controller_file",
    "pid_controller",
]
