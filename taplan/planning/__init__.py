"""Planners that compose the scene, IK and timing: collision-free motion in a scene (:func:`plan_motion`) and
Cartesian straight lines through IK (:func:`cartesian_line`), and re-planning in the control loop (:class:`Replanner`).

Layer order: robot -> scene -> ik / timing / stream -> planning -> trajectory -> reference / check.
"""

from __future__ import annotations

from taplan.planning.cartesian import CartesianResult, cartesian_line, cartesian_offset
from taplan.planning.clearance import SceneClearance, scene_clearance
from taplan.planning.motion import MotionPlan, PlanReport, plan_motion
from taplan.planning.optimize import OptimizedPath, optimize_path
from taplan.planning.replan import ReplanEvent, Replanner
from taplan.planning.rrt import rrt_connect, shortcut
from taplan.planning.seen import LookRound, SeenPlan, plan_seen
from taplan.planning.verify import SegmentCheck, Verification, check_segment, check_segments, verify_trajectory

__all__ = [
    "cartesian_line",
    "cartesian_offset",
    "CartesianResult",
    "plan_motion",
    "MotionPlan",
    "PlanReport",
    "check_segment",
    "check_segments",
    "Replanner",
    "ReplanEvent",
    "scene_clearance",
    "SceneClearance",
    "verify_trajectory",
    "SegmentCheck",
    "Verification",
    "optimize_path",
    "OptimizedPath",
    "rrt_connect",
    "shortcut",
    "plan_seen",
    "SeenPlan",
    "LookRound",
]
