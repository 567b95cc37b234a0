"""Time parameterisation: TOPP-RA retiming that never exceeds the limits, jerk-limited trajectories, casadi
trajectory optimisation, Cartesian straight lines through IK, and dual-arm synchronisation.

Module map: :mod:`~taplan.timing.path` (geometric path ``q(s)``), :mod:`~taplan.timing.constraints` (toppra
constraint exact on grid segments), :mod:`~taplan.timing.toppra_retime` (``retime``),
:mod:`~taplan.timing.jerk_limited` (TOPP-RA + moving-average filter of the path
timing), :mod:`~taplan.timing.sync` (dual-arm time base), :mod:`~taplan.timing.limits_check` (exact peak usage of
the limits), :mod:`~taplan.timing.cartesian` (straight-line end-effector motions through IK),
:mod:`~taplan.timing.optimize` (casadi/ipopt minimum-time or minimum-jerk trajectories).
"""

from __future__ import annotations

from taplan.timing.cartesian import CartesianResult, cartesian_line, cartesian_offset, line_deviation
from taplan.timing.jerk_limited import JerkLimitedResult, filter_profile, jerk_limited
from taplan.timing.limits_check import LimitUsage, limit_usage, sampled_limit_usage
from taplan.timing.optimize import OptimizationResult, optimize
from taplan.timing.path import Path
from taplan.timing.sync import split, synchronise
from taplan.timing.toppra_retime import PathProfile, grid_for, retime, time_optimal_profile

__all__ = [
    "CartesianResult",
    "cartesian_line",
    "cartesian_offset",
    "line_deviation",
    "JerkLimitedResult",
    "LimitUsage",
    "OptimizationResult",
    "Path",
    "PathProfile",
    "filter_profile",
    "grid_for",
    "jerk_limited",
    "limit_usage",
    "optimize",
    "retime",
    "sampled_limit_usage",
    "split",
    "synchronise",
    "time_optimal_profile",
]
