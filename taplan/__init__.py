"""taplan: optimisation-based motion planning for the TeleAvatar dual arm and any robot pinocchio loads.

Top level: :class:`Robot`, :class:`JointLimits`, :class:`Trajectory`, :func:`check` and the errors. Capabilities
live in subpackages, imported on first use: ``taplan.ik`` (QP differential IK), ``taplan.timing`` (TOPP-RA,
jerk-limited, casadi, Cartesian lines), ``taplan.stream`` (ruckig streaming), ``taplan.reference`` (controller
models), ``taplan.api`` (``/api`` payloads and scheduling), ``taplan.ros`` (optional ROS 2 node).
"""

from __future__ import annotations

import importlib
import logging
from typing import Any

from taplan import clearance as _clearance  # noqa: F401 (registers check()'s collision half)
from taplan.check import Report, Thresholds, check
from taplan.errors import (
    ConfigError,
    InfeasibleError,
    InvalidInputError,
    InvalidLimitsError,
    SolverError,
    StreamError,
    TaplanError,
    TimingError,
    UnknownNameError,
)
from taplan.limits import DEFAULT_PLANNING_SCALING, JointLimits, PlanningScaling
from taplan.robot import ArmGroup, Robot
from taplan.trajectory import Trajectory, Waypoint, concatenate

logging.getLogger(__name__).addHandler(logging.NullHandler())

__version__ = "0.1.0"

_SUBPACKAGES = ("api", "ik", "timing", "stream", "reference", "ros", "demo", "plots")

__all__ = [
    "ArmGroup",
    "ConfigError",
    "DEFAULT_PLANNING_SCALING",
    "InfeasibleError",
    "InvalidInputError",
    "InvalidLimitsError",
    "JointLimits",
    "PlanningScaling",
    "Report",
    "Robot",
    "SolverError",
    "StreamError",
    "TaplanError",
    "Thresholds",
    "TimingError",
    "Trajectory",
    "UnknownNameError",
    "Waypoint",
    "__version__",
    "check",
    "concatenate",
]


def __getattr__(name: str) -> Any:
    if name in _SUBPACKAGES:
        return importlib.import_module(f"taplan.{name}")
    raise AttributeError(f"module 'taplan' has no attribute {name!r}")
