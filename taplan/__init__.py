"""taplan: optimisation-based motion planning for the TeleAvatar dual arm and any robot pinocchio loads."""

from __future__ import annotations

import logging

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

logging.getLogger(__name__).addHandler(logging.NullHandler())

__version__ = "0.1.0"

__all__ = [
    "ArmGroup",
    "ConfigError",
    "DEFAULT_PLANNING_SCALING",
    "InfeasibleError",
    "InvalidInputError",
    "InvalidLimitsError",
    "JointLimits",
    "PlanningScaling",
    "Robot",
    "SolverError",
    "StreamError",
    "TaplanError",
    "TimingError",
    "UnknownNameError",
    "__version__",
]
