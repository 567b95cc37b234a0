"""A fast yes/no clearance test for the sampler: is every active pair of a :class:`~taplan.scene.CollisionWorld`
at least ``clearance`` apart at a configuration? One call into C++.

The world's bodies (robot capsules, obstacles, attached objects) and its active pairs are rebuilt as a pinocchio
``GeometryModel`` whose collision requests carry coal's ``security_margin = clearance``: ``computeCollisions`` then
answers "some pair is closer than ``clearance``" after forward kinematics, stopping at the first such pair, in about
0.01 ms where a full distance evaluation in Python takes milliseconds. A broad phase (coal's dynamic AABB tree,
pinocchio's ``BroadPhaseManager``) hands only the pairs whose boxes overlap to the narrow phase: two arms among many
obstacles cost about what one arm among few does. The sampler explores with it; it certifies
nothing. Perceived occupancy (voxels that answer their own distances) is tested beside it by
:class:`~taplan.planning.field_check.FieldClearance` (bounds from the voxels' surface, exact where they are close).
Every path it finds is certified afterwards by conservative advancement (:func:`~taplan.planning.verify.
check_segment`), which stays the planner's only guarantee.

The geometry model is built once per world and scene version (a build took ~20 ms; the sampler makes several
tests per plan: per arm, per margin, the smoothing); each test has its own data with the pairs it needs active.

Given the joints that move (``active``), the pairs whose two members both stay put (an obstacle, the torso, the held
arm) are left out: their distance is that of the start, which the planner checked before sampling; a one-arm search
then tests about half the pairs.

A motion between two configurations is tested at states spaced so that no robot point moves more than ``spacing``
between them (``Σ reach_j |Δq_j|``), in bisection order (the middle first: a blocked motion is usually found early).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
import pinocchio as pin

from taplan.scene.world import CollisionWorld

__all__ = ["ClearanceCheck"]


def _capsule_placement(start: np.ndarray, end: np.ndarray) -> pin.SE3:
    """The capsule's centre with its z axis along the segment (coal's capsules are centred on z)."""
    axis = end - start
    length = float(np.linalg.norm(axis))
    z = axis / length if length > 1e-12 else np.array([0.0, 0.0, 1.0])
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return pin.SE3(np.column_stack([x, np.cross(z, x), z]), (start + end) / 2)


@lru_cache(maxsize=1024)
def _bisection_order(count: int) -> np.ndarray:
    """Fractions k / count for k = 1..count: the end first, then coarse to fine (k with more trailing zero bits
    first: the middle, the quarters, ...; exactly bisection when ``count`` is a power of two)."""
    k = np.arange(1, count)
    order = k[np.argsort(-(k & -k), kind="stable")]
    return np.concatenate([[count], order]) / count


def _moved_by(model: pin.Model, joint: int, active: np.ndarray) -> bool:
    """Whether a body carried by ``joint`` moves when the configuration entries ``active`` change."""
    indices = {int(i) for i in np.asarray(active).ravel()}
    return any(model.joints[j].idx_q in indices for j in model.supports[joint] if j > 0)


@dataclass(frozen=True)
class _Geometry:
    """A world's bodies and every active pair as a pinocchio ``GeometryModel`` (``pairs`` in its pair order) and the
    joint carrying each body (``joints``, by name)."""

    geometry: Any
    pairs: list[tuple[str, str]]
    joints: dict[str, int]


# per world, the geometry of its current bodies and scene: the sampler builds several tests per plan (per arm, per
# margin, the smoothing) and a build took ~20 ms (a distance evaluation for the pair list, a placement per capsule)
_BUILT: weakref.WeakKeyDictionary[CollisionWorld, tuple[Any, _Geometry]] = weakref.WeakKeyDictionary()


def _geometry(world: CollisionWorld) -> _Geometry:
    import coal

    robot = world.robot
    key = (world.scene.version, tuple((b.name, b.joint, b.radius, *b.start, *b.end) for b in world.bodies))
    cached = _BUILT.get(world)
    if cached is not None and cached[0] == key:
        return cached[1]
    geometry = pin.GeometryModel()
    ids: dict[str, int] = {}
    for body in world.bodies:
        length = float(np.linalg.norm(body.end - body.start))
        shape = coal.Capsule(body.radius, length) if length > 1e-9 else coal.Sphere(body.radius)
        placement = _capsule_placement(np.asarray(body.start, float), np.asarray(body.end, float))
        ids[body.name] = geometry.addGeometryObject(pin.GeometryObject(body.name, body.joint, placement, shape))
    for obstacle in world.scene.obstacles.values():
        if hasattr(obstacle.shape, "capsule_distances"):
            continue  # perceived occupancy: tested by ClearanceCheck.fields
        placement = pin.SE3(obstacle.pose[:3, :3], obstacle.pose[:3, 3])
        ids[obstacle.name] = geometry.addGeometryObject(
            pin.GeometryObject(obstacle.name, 0, placement, obstacle.shape.to_coal())
        )
    for attached in world.scene.attached.values():
        frame = robot.model.frames[robot.frame_id(attached.frame)]
        placement = frame.placement * pin.SE3(attached.pose[:3, :3], attached.pose[:3, 3])
        ids[attached.name] = geometry.addGeometryObject(
            pin.GeometryObject(attached.name, frame.parentJoint, placement, attached.shape.to_coal())
        )
    pairs = [(a, b) for a, b in world.distances(robot.home, jacobian=False).pairs if a in ids and b in ids]
    for a, b in pairs:
        geometry.addCollisionPair(pin.CollisionPair(ids[a], ids[b]))
    joints = {geometry.geometryObjects[i].name: geometry.geometryObjects[i].parentJoint for i in ids.values()}
    built = _Geometry(geometry, pairs, joints)
    _BUILT[world] = (key, built)
    return built


class ClearanceCheck:
    """Whether a configuration keeps ``clearance`` [m] on every active pair of ``world`` (see the module); with
    ``active`` (configuration indices), on the pairs that those joints move."""

    def __init__(self, world: CollisionWorld, clearance: float, active: np.ndarray | None = None) -> None:
        robot = world.robot
        world.max_point_speed_bound(robot.home, robot.home)  # brings the world's attached objects and reach up to date
        self.world = world
        self.clearance = float(clearance)
        self.model = robot.model
        self.data = self.model.createData()
        self.reach = world.reach.copy()
        self.checks = 0  # configurations tested (a measure of the sampler's work)
        self.geometry: Any = None
        self.fields: Any = None
        if any(hasattr(o.shape, "capsule_distances") for o in world.scene.obstacles.values()):
            from taplan.planning.field_check import FieldClearance

            self.fields = FieldClearance(world, self.clearance, active)
            if not self.fields.ready:
                return  # no distance engine for the bodies' segments: the world's (slower) test is used
        built = _geometry(world)
        self.geometry = built.geometry
        keep = np.ones(len(built.pairs), dtype=bool)
        if active is not None:
            moving = {name for name, joint in built.joints.items() if _moved_by(self.model, joint, active)}
            keep = np.array([a in moving or b in moving for a, b in built.pairs], dtype=bool)
        self.pairs = [pair for pair, k in zip(built.pairs, keep, strict=True) if k]
        self.geometry_data = pin.GeometryData(self.geometry)
        for index in np.flatnonzero(~keep):
            self.geometry_data.deactivateCollisionPair(int(index))
        for request in self.geometry_data.collisionRequests:
            request.security_margin = self.clearance
        # coal's dynamic AABB tree as the broad phase: only the active pairs whose boxes (grown by the margin) overlap
        # reach the narrow phase. The same verdicts as the loop over every active pair (tests), at 14-17 us per state
        # instead of 14 us (one arm, 180 pairs), 30-32 us (two arms, 320-340 pairs: window, cabinet) and 156 us
        # (two arms among 18 boxes, 735 pairs) on the benchmark's scenes (issue 22's profile: the sampled route's
        # smoothing is these tests)
        self.broadphase = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(
            self.model, self.geometry, self.geometry_data
        )

    def __call__(self, q: np.ndarray) -> bool:
        """True when every active pair is at least ``clearance`` apart at ``q`` (nq,)."""
        self.checks += 1
        if self.geometry is None:
            return not self.world.in_collision(q, margin=self.clearance)
        if pin.computeCollisions(self.model, self.data, self.broadphase, q, True):
            return False
        return self.fields is None or self.fields(q)

    def motion(self, q_a: np.ndarray, q_b: np.ndarray, spacing: float) -> bool:
        """True when every state tested along the straight segment keeps ``clearance``: ``q_b`` first, then states
        no more than ``spacing`` [m] of robot-point travel apart, in bisection order (``q_a`` is not tested)."""
        travel = float(self.reach @ np.abs(q_b - q_a))
        count = max(1, int(np.ceil(travel / spacing)))
        states = q_a + _bisection_order(count)[:, None] * (q_b - q_a)
        if self.fields is None or self.geometry is None or count == 1:
            return all(self(q) for q in states)
        # occupancy: the end alone (a blocked extension usually fails there), then the compiled pairs state by
        # state and the occupancy for every other state in one batch (a query per call costs far more than a state)
        if not self(states[0]):
            return False
        self.checks += count - 1
        rest = states[1:]
        if any(pin.computeCollisions(self.model, self.data, self.broadphase, q, True) for q in rest):
            return False
        return bool(self.fields.many(rest).all())
