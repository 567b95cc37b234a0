"""Time parameterisation: TOPP-RA retiming that never exceeds the limits, jerk-limited trajectories, casadi
trajectory optimisation and dual-arm synchronisation (Cartesian straight lines through IK are a planner:
:mod:`taplan.planning.cartesian`).

Module map: :mod:`~taplan.timing.path` (geometric path ``q(s)``), :mod:`~taplan.timing.constraints` (toppra
constraint exact on grid segments), :mod:`~taplan.timing.toppra_retime` (``retime``),
:mod:`~taplan.timing.jerk_limited` (TOPP-RA + moving-average filter of the path
timing), :mod:`~taplan.timing.sync` (dual-arm time base), :mod:`~taplan.timing.limits_check` (exact peak usage of
the limits),
:mod:`~taplan.timing.straight` (time-optimal jerk-limited straight joint-space segment, ruckig),
:mod:`~taplan.timing.optimize` (casadi/ipopt minimum-time or minimum-jerk trajectories),
:mod:`~taplan.timing.demonstration` (recorded demonstrations into jerk-limited trajectories).
"""

from __future__ import annotations

from taplan.timing.demonstration import DemonstrationResult, Slowdown, load_recording, time_demonstration
from taplan.timing.jerk_limited import JerkLimitedResult, filter_profile, jerk_limited
from taplan.timing.limits_check import LimitUsage, limit_usage, sampled_limit_usage
from taplan.timing.optimize import OptimizationResult, optimize
from taplan.timing.path import Path
from taplan.timing.straight import straight_line
from taplan.timing.sync import split, synchronise
from taplan.timing.toppra_retime import PathProfile, grid_for, retime, time_optimal_profile

__all__ = [
    "DemonstrationResult",
    "JerkLimitedResult",
    "LimitUsage",
    "OptimizationResult",
    "Path",
    "PathProfile",
    "filter_profile",
    "grid_for",
    "jerk_limited",
    "limit_usage",
    "load_recording",
    "optimize",
    "retime",
    "sampled_limit_usage",
    "split",
    "straight_line",
    "Slowdown",
    "synchronise",
    "time_demonstration",
    "time_optimal_profile",
]
