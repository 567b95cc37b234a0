"""Limits of the differential IK: velocity bounds (box) and soft inequality rows."""

from taplan.ik.limits.acceleration_limit import AccelerationLimit, TargetBraking
from taplan.ik.limits.collision_limit import CollisionLimit, capsule_pair_distance
from taplan.ik.limits.limit import BoxLimit, RowLimit, StepContext, intersect_relaxed
from taplan.ik.limits.position_limit import PositionLimit
from taplan.ik.limits.scene_limit import SceneLimit
from taplan.ik.limits.velocity_limit import VelocityLimit

__all__ = [
    "BoxLimit",
    "RowLimit",
    "StepContext",
    "intersect_relaxed",
    "VelocityLimit",
    "PositionLimit",
    "AccelerationLimit",
    "TargetBraking",
    "CollisionLimit",
    "capsule_pair_distance",
    "SceneLimit",
]
