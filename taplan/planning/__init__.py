"""Planners that compose the scene, IK and timing: collision-free motion in a scene (:func:`plan_motion`).

Layer order: robot -> scene -> ik / timing / stream -> planning. Cartesian straight lines through IK are in
:mod:`taplan.timing.cartesian`.
"""

from __future__ import annotations

from taplan.planning.motion import MotionPlan, PlanReport, plan_motion
from taplan.planning.optimize import OptimizedPath, optimize_path
from taplan.planning.rrt import rrt_connect, shortcut
from taplan.planning.verify import SegmentCheck, Verification, check_segment, verify_trajectory

__all__ = [
    "plan_motion",
    "MotionPlan",
    "PlanReport",
    "check_segment",
    "verify_trajectory",
    "SegmentCheck",
    "Verification",
    "optimize_path",
    "OptimizedPath",
    "rrt_connect",
    "shortcut",
]
