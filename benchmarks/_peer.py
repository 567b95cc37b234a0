"""A fair OMPL peer and the independent dense check of ``bench_planning``, both on compiled collision checking.

``CompiledScene`` rebuilds a :class:`~taplan.scene.CollisionWorld`'s bodies (the robot's capsules, the scene's
obstacles and attached objects) and its active pairs as a pinocchio ``GeometryModel``: a validity check is then one
call into C++ (``pin.computeCollisions``, coal underneath), the check a user of OMPL with pinocchio would write.
Its distances (``pin.computeDistances``) do not go through taplan's distance code (closed-form capsule pairs,
broad phase, Jacobians), so the dense check that certifies both planners is independent of taplan's planner.

``motion_resolution`` chooses OMPL's motion-check resolution so that no point of the robot moves more than half
of the thinnest obstacle between two checked states: a motion cannot step through a wall or a pole.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from taplan.scene import CollisionWorld

THINNEST = 0.02  # [m] the thinnest obstacle of the suite (2 cm walls, panels and boards; 2 cm poles)


def _capsule_frame(start: np.ndarray, end: np.ndarray) -> pin.SE3:
    """The capsule's centre, its z axis along the segment (any perpendicular x)."""
    axis = end - start
    length = float(np.linalg.norm(axis))
    z = axis / length if length > 1e-12 else np.array([0.0, 0.0, 1.0])
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return pin.SE3(np.column_stack([x, np.cross(z, x), z]), (start + end) / 2)


class CompiledScene:
    """The world's bodies and active pairs as a pinocchio geometry model (C++ collision and distance calls)."""

    def __init__(self, world: CollisionWorld) -> None:
        import coal

        robot = world.robot
        self.model = robot.model
        self.data = self.model.createData()
        self.geometry = pin.GeometryModel()
        ids: dict[str, int] = {}
        for body in world.bodies:
            length = float(np.linalg.norm(body.end - body.start))
            shape = coal.Capsule(body.radius, length) if length > 1e-9 else coal.Sphere(body.radius)
            placement = _capsule_frame(np.asarray(body.start, float), np.asarray(body.end, float))
            ids[body.name] = self.geometry.addGeometryObject(
                pin.GeometryObject(body.name, body.joint, placement, shape)
            )
        for obstacle in world.scene.obstacles.values():
            placement = pin.SE3(obstacle.pose[:3, :3], obstacle.pose[:3, 3])
            ids[obstacle.name] = self.geometry.addGeometryObject(
                pin.GeometryObject(obstacle.name, 0, placement, obstacle.shape.to_coal())
            )
        for attached in world.scene.attached.values():
            frame = self.model.frames[robot.frame_id(attached.frame)]
            placement = frame.placement * pin.SE3(attached.pose[:3, :3], attached.pose[:3, 3])
            ids[attached.name] = self.geometry.addGeometryObject(
                pin.GeometryObject(attached.name, frame.parentJoint, placement, attached.shape.to_coal())
            )
        self.pairs = world.distances(robot.home, jacobian=False).pairs  # the world's active pairs, by name
        for a, b in self.pairs:
            self.geometry.addCollisionPair(pin.CollisionPair(ids[a], ids[b]))
        self.geometry_data = pin.GeometryData(self.geometry)
        for request in self.geometry_data.distanceRequests:
            request.enable_signed_distance = True

    def valid(self, q: np.ndarray) -> bool:
        """No active pair in contact (coal's collision test), one C++ call."""
        return not pin.computeCollisions(self.model, self.data, self.geometry, self.geometry_data, q, True)

    def min_distance(self, q: np.ndarray) -> float:
        """The smallest signed distance [m] over the active pairs (coal, through pinocchio)."""
        pin.computeDistances(self.model, self.data, self.geometry, self.geometry_data, q)
        return min((r.min_distance for r in self.geometry_data.distanceResults), default=np.inf)


def motion_resolution(world: CollisionWorld, active: np.ndarray, extent: float) -> float:
    """OMPL's state-validity-checking resolution (a fraction of the space's ``extent``) such that no robot point
    moves more than ``THINNEST / 2`` between checked states: ``Σ reach_j |Δq_j| <= ‖reach‖₂ ‖Δq‖₂`` (Cauchy-Schwarz),
    and OMPL spaces its checks ``resolution · extent`` apart in the Euclidean norm."""
    world.max_point_speed_bound(world.robot.home, world.robot.home)  # makes the world include attached objects
    step = (THINNEST / 2) / float(np.linalg.norm(world.reach[active]))
    return min(step / extent, 0.01)


def dense_check(
    scene: CompiledScene, world: CollisionWorld, evaluate: Any, duration: float, hold: np.ndarray, index: np.ndarray
) -> tuple[int, float]:
    """(samples in collision, min clearance [m]) of a timed trajectory, sampled so that no link point moves more
    than ``TRAVEL`` between samples (bound ``Σ reach |Δq|``), distances from the compiled scene."""
    t, dt = 0.0, 1e-3
    collisions, lowest = 0, np.inf
    q_prev = None
    while True:
        q = hold.copy()
        q[index] = evaluate(min(t, duration))
        if q_prev is not None and world.max_point_speed_bound(q_prev, q) > TRAVEL and dt > 1e-6:
            t -= dt
            dt /= 2
            t += dt
            continue
        d = scene.min_distance(q)
        lowest = min(lowest, d)
        collisions += int(d < 0)
        if t >= duration:
            return collisions, float(lowest)
        q_prev = q
        t += dt
        dt *= 1.5


TRAVEL = 1e-3  # [m] link-point travel between samples of the independent check
