"""A fast yes/no clearance test for the sampler: is every active pair of a :class:`~taplan.scene.CollisionWorld`
at least ``clearance`` apart at a configuration, or at every state tested along a motion?

The robot's own pairs and its capsules against closed-form obstacles (boxes, spheres, capsules, cylinders,
half-spaces: every pair of the benchmark's scenes) are tested by a compiled loop
(:mod:`~taplan.planning.clearance_kernel`): bounding spheres first, then the distance engine's closed forms for
the pairs they leave within ``clearance``, with the bodies' end points from the compiled kinematics, 2-6 µs per
state where coal through pinocchio took 14-23 µs (issue 22). The pairs without a closed form (attached objects,
meshes) stay with coal: the world's bodies are rebuilt as a pinocchio ``GeometryModel`` whose collision requests
carry ``security_margin = clearance``, only those pairs active, with coal's dynamic AABB tree as the broad phase.
Perceived occupancy (voxels that answer their own distances) is tested beside them by
:class:`~taplan.planning.field_check.FieldClearance` (bounds from the voxels' surface, exact where they are close).
The sampler explores with it; it certifies nothing. Every path it finds is certified afterwards by conservative
advancement (:func:`~taplan.planning.verify.check_segment`), which stays the planner's only guarantee.

The pair lists (and coal's geometry model, when needed) are built once per world and scene version (a build took
~20 ms; the sampler makes several tests per plan: per arm, per margin, the smoothing).

Given the joints that move (``active``), the pairs whose two members both stay put (an obstacle, the torso, the held
arm) are left out: their distance is that of the start, which the planner checked before sampling; a one-arm search
then tests about half the pairs.

A motion between two configurations is tested at states spaced so that no robot point moves more than ``spacing``
between them (``Σ reach_j |Δq_j|``): the end first, then in bisection order (the middle first: a blocked motion is
usually found early), each state's kinematics computed only when the states before it were clear.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
import pinocchio as pin

from taplan.errors import InvalidInputError
from taplan.planning.clearance_kernel import first_blocked_along, first_too_close
from taplan.scene.engine import end_point_kernel, shape_code, shape_size
from taplan.scene.pair_kernels import HALF_SPACE
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
    """Pairs of a world's bodies as a pinocchio ``GeometryModel`` holding their members only (``pairs`` in its pair
    order)."""

    geometry: Any
    pairs: list[tuple[str, str]]


# per world, the geometry of its current bodies and scene for each set of pairs asked: the sampler builds several
# tests per plan (per arm, per margin, the smoothing) and a build took ~5 ms (a placement per capsule)
_BUILT: weakref.WeakKeyDictionary[CollisionWorld, tuple[Any, dict]] = weakref.WeakKeyDictionary()


def _geometry(world: CollisionWorld, only: frozenset[tuple[str, str]] | None = None) -> _Geometry:
    """The pairs ``only`` (None: every pair of the world but occupancy's) as coal geometry: a model of just their
    members, so that pinocchio places and coal's broad phase sorts those alone (an attached cup's pairs beside the
    compiled test cost what those few objects cost, not what all the bodies do)."""
    import coal

    robot = world.robot
    pairs = [pair for pair in _split(world).pairs if only is None or pair in only]
    key = (world.scene.version, tuple((b.name, b.joint, b.radius, *b.start, *b.end) for b in world.bodies))
    cached = _BUILT.get(world)
    if cached is None or cached[0] != key:
        cached = (key, {})
        _BUILT[world] = cached
    found = cached[1].get(only)
    if found is not None:
        return found
    members = {name for pair in pairs for name in pair}
    geometry = pin.GeometryModel()
    ids: dict[str, int] = {}
    for body in world.bodies:
        if body.name not in members:
            continue
        length = float(np.linalg.norm(body.end - body.start))
        shape = coal.Capsule(body.radius, length) if length > 1e-9 else coal.Sphere(body.radius)
        placement = _capsule_placement(np.asarray(body.start, float), np.asarray(body.end, float))
        ids[body.name] = geometry.addGeometryObject(pin.GeometryObject(body.name, body.joint, placement, shape))
    for obstacle in world.scene.obstacles.values():
        if obstacle.name not in members:
            continue
        placement = pin.SE3(obstacle.pose[:3, :3], obstacle.pose[:3, 3])
        ids[obstacle.name] = geometry.addGeometryObject(
            pin.GeometryObject(obstacle.name, 0, placement, obstacle.shape.to_coal())
        )
    for attached in world.scene.attached.values():
        if attached.name not in members:
            continue
        frame = robot.model.frames[robot.frame_id(attached.frame)]
        placement = frame.placement * pin.SE3(attached.pose[:3, :3], attached.pose[:3, 3])
        ids[attached.name] = geometry.addGeometryObject(
            pin.GeometryObject(attached.name, frame.parentJoint, placement, attached.shape.to_coal())
        )
    for a, b in pairs:
        geometry.addCollisionPair(pin.CollisionPair(ids[a], ids[b]))
    built = _Geometry(geometry, pairs)
    cached[1][only] = built
    return built


@dataclass(frozen=True)
class _Pairs:
    """A world's active pairs (those of ``world.distances``, without perceived occupancy) split between the compiled
    test (robot pairs; robot bodies against closed-form obstacles) and coal (attached objects, meshes), with the
    kernel's arrays (:func:`~taplan.planning.clearance_kernel.first_too_close`) and the joint carrying each member."""

    pairs: list[tuple[str, str]]
    compiled: np.ndarray  # per pair: True for the kernel's
    self_a: np.ndarray  # per pair: the robot pair's bodies (-1: not a robot pair)
    self_b: np.ndarray
    body: np.ndarray  # per pair: the body and the obstacle of a robot-obstacle pair (-1: not one)
    obstacle: np.ndarray
    obstacles: tuple[np.ndarray, ...]  # kind, rotation, center, size, core, bounding per closed-form obstacle
    radius: np.ndarray
    joints: dict[str, int]
    segments: Any  # Q (N, nq) -> the bodies' end points (N, B, 2, 3): the engine's kinematics
    kinematics: Any  # the compiled q -> end points (a NativeFunction), or None (no C compiler)


_SPLIT: weakref.WeakKeyDictionary[CollisionWorld, tuple[Any, _Pairs]] = weakref.WeakKeyDictionary()


def _split(world: CollisionWorld) -> _Pairs:
    from taplan.scene.engine import DistanceEngine

    robot = world.robot
    key = (world.scene.version, tuple((b.name, b.joint, b.radius, *b.start, *b.end) for b in world.bodies))
    cached = _SPLIT.get(world)
    if cached is not None and cached[0] == key:
        return cached[1]
    bodies = {b.name: k for k, b in enumerate(world.bodies)}
    solids = {
        name: o
        for name, o in world.scene.obstacles.items()
        if not hasattr(o.shape, "capsule_distances") and shape_code(o.shape) >= 0
    }
    index = {name: k for k, name in enumerate(solids)}
    fields = {name for name, o in world.scene.obstacles.items() if hasattr(o.shape, "capsule_distances")}
    pairs = [
        (a, b)
        for a, b in world.distances(robot.home, jacobian=False, bound_beyond=-math.inf).pairs  # names only
        if a not in fields and b not in fields
    ]
    P = len(pairs)
    self_a, self_b, body, obstacle = (np.full(P, -1, dtype=np.int64) for _ in range(4))
    for k, (a, b) in enumerate(pairs):
        if a in bodies and b in bodies:
            self_a[k], self_b[k] = bodies[a], bodies[b]
        elif a in bodies and b in index:
            body[k], obstacle[k] = bodies[a], index[b]
    shapes = [o.shape for o in solids.values()]
    obstacles = (
        np.array([shape_code(s) for s in shapes], dtype=np.int64),
        np.array([o.pose[:3, :3] for o in solids.values()], dtype=float).reshape(-1, 3, 3),
        np.array([o.pose[:3, 3] for o in solids.values()], dtype=float).reshape(-1, 3),
        np.array([shape_size(s) for s in shapes], dtype=float).reshape(-1, 3),
        np.array([getattr(s, "radius", 0.0) for s in shapes], dtype=float),
        np.array([0.0 if shape_code(s) == HALF_SPACE else s.bounding_radius() for s in shapes], dtype=float),
    )
    joints = {b.name: b.joint for b in world.bodies} | {name: 0 for name in world.scene.obstacles}
    for attached in world.scene.attached.values():
        joints[attached.name] = robot.model.frames[robot.frame_id(attached.frame)].parentJoint
    engine = world.engine() or DistanceEngine(world)  # its kinematics only: any scene
    split = _Pairs(
        pairs,
        (self_a >= 0) | (body >= 0),
        self_a,
        self_b,
        body,
        obstacle,
        obstacles,
        np.array([b.radius for b in world.bodies], dtype=float),
        joints,
        engine.segments,
        end_point_kernel(world),
    )
    _SPLIT[world] = (key, split)
    return split


_ALONE = np.zeros(1)  # one state: q + 0 (q - q)
# coal's pairs (attached objects, meshes) above which its AABB tree is worth its upkeep: an attached cup's 35 pairs
# cost 5.8 us per state in a loop and 14.4 us through the tree; 180 capsule pairs cost about the same both ways
# (issue 22's profile), 735 far less through the tree
BROAD_PHASE_PAIRS = 150


def _native_buffers(kinematics: Any, nq: int, outputs: int) -> tuple[Any, ...] | None:
    """The compiled kinematics' entry point with buffers of this test's own, as :func:`first_blocked_along` takes
    them: ``nq`` inputs, ``outputs`` end point coordinates (no lock: a test is used by one thread at a time, and
    tests in other threads have their own buffers)."""
    if kinematics is None:
        return None
    n_arg, n_res, n_iw, n_w = kinematics.sizes
    q, e = np.zeros(nq), np.zeros(outputs)
    arg, res = np.zeros(max(n_arg, 1), dtype=np.uint64), np.zeros(max(n_res, 1), dtype=np.uint64)
    arg[0], res[0] = q.ctypes.data, e.ctypes.data
    return (kinematics.address, arg, res, np.zeros(max(n_iw, 1), dtype=np.int64), np.zeros(max(n_w, 1)), q, e)


class ClearanceCheck:
    """Whether a configuration keeps ``clearance`` [m] (>= 0) on every active pair of ``world`` (see the module);
    with ``active`` (configuration indices), on the pairs that those joints move."""

    def __init__(self, world: CollisionWorld, clearance: float, active: np.ndarray | None = None) -> None:
        if not (isinstance(clearance, (int, float, np.floating)) and math.isfinite(clearance) and clearance >= 0):
            raise InvalidInputError("clearance", clearance, "a distance >= 0 [m]")
        robot = world.robot
        world.max_point_speed_bound(robot.home, robot.home)  # brings the world's attached objects and reach up to date
        self.world = world
        self.clearance = float(clearance)
        self.model = robot.model
        self.data = self.model.createData()
        self.reach = world.reach.copy()
        self.checks = 0  # configurations tested (a measure of the sampler's work)
        self.ready = False  # False: the world's own (slower) test answers
        self.geometry: Any = None  # coal's pairs (attached objects, meshes), or None when every pair is compiled
        self.fields: Any = None
        if any(hasattr(o.shape, "capsule_distances") for o in world.scene.obstacles.values()):
            from taplan.planning.field_check import FieldClearance

            self.fields = FieldClearance(world, self.clearance, active)
            if not self.fields.ready:
                return  # no distance engine for the bodies' segments: the world's (slower) test is used
        split = _split(world)
        keep = np.ones(len(split.pairs), dtype=bool)
        if active is not None:
            joints = set(split.joints.values())
            moved = {j: _moved_by(self.model, j, active) for j in joints}
            moving = {name for name, joint in split.joints.items() if moved[joint]}
            keep = np.array([a in moving or b in moving for a, b in split.pairs], dtype=bool)
        self.pairs = [pair for pair, k in zip(split.pairs, keep, strict=True) if k]
        mine = keep & split.compiled
        robot_pairs, obstacle_pairs = mine & (split.self_a >= 0), mine & (split.body >= 0)
        self._pairs = (
            split.radius,
            split.self_a[robot_pairs],
            split.self_b[robot_pairs],
            split.body[obstacle_pairs],
            split.obstacle[obstacle_pairs],
            *split.obstacles,
        )
        self._segments = split.segments
        self._native = _native_buffers(split.kinematics, self.model.nq, 6 * len(split.radius))
        self.ready = True
        coal_pairs = {pair for pair, k in zip(split.pairs, keep & ~split.compiled, strict=True) if k}
        if not coal_pairs:
            return
        built = _geometry(world, frozenset(coal_pairs))
        self.geometry = built.geometry
        self.geometry_data = pin.GeometryData(self.geometry)
        for request in self.geometry_data.collisionRequests:
            request.security_margin = self.clearance
        self.broadphase: Any = None
        if len(coal_pairs) > BROAD_PHASE_PAIRS:  # coal's dynamic AABB tree: only the pairs whose boxes (grown by
            # the margin) overlap reach the narrow phase
            self.broadphase = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(
                self.model, self.geometry, self.geometry_data
            )

    def _first_blocked(self, q_a: np.ndarray, q_b: np.ndarray, fractions: np.ndarray) -> int:
        """The index of the first of the states ``q_a + f (q_b - q_a)``, ``f`` in ``fractions``, with a compiled or
        coal pair closer than the clearance, or -1 (occupancy is not tested here)."""
        if self._native is not None:
            first = int(first_blocked_along(self._native, q_a, q_b, fractions, self._pairs, self.clearance))
            if first == -2:
                raise RuntimeError("the compiled kinematics of the clearance test failed")
        else:  # no C compiler: the engine's kinematics (pinocchio) for every state, then the kernel
            ends, _ = self._segments(q_a + fractions[:, None] * (q_b - q_a), jacobian=False)
            first = int(first_too_close(ends, self._pairs, self.clearance))
        if self.geometry is not None:
            for k in range(len(fractions) if first < 0 else first):
                q = q_a + fractions[k] * (q_b - q_a)
                if self._coal_blocked(q):
                    return k
        return first

    def _coal_blocked(self, q: np.ndarray) -> bool:
        if self.broadphase is not None:
            return pin.computeCollisions(self.model, self.data, self.broadphase, q, True)
        return pin.computeCollisions(self.model, self.data, self.geometry, self.geometry_data, q, True)

    def __call__(self, q: np.ndarray) -> bool:
        """True when every active pair is at least ``clearance`` apart at ``q`` (nq,)."""
        self.checks += 1
        if not self.ready:
            return not self.world.in_collision(q, margin=self.clearance)
        q = np.asarray(q, dtype=float)
        if self._first_blocked(q, q, _ALONE) >= 0:
            return False
        return self.fields is None or self.fields(q)

    def motion(self, q_a: np.ndarray, q_b: np.ndarray, spacing: float) -> bool:
        """True when every state tested along the straight segment keeps ``clearance``: ``q_b`` first, then states
        no more than ``spacing`` [m] of robot-point travel apart, in bisection order (``q_a`` is not tested)."""
        travel = float(self.reach @ np.abs(q_b - q_a))
        count = max(1, int(np.ceil(travel / spacing)))
        fractions = _bisection_order(count)
        if not self.ready:
            return all(self(q) for q in q_a + fractions[:, None] * (q_b - q_a))
        q_a, q_b = np.asarray(q_a, dtype=float), np.asarray(q_b, dtype=float)
        blocked = self._first_blocked(q_a, q_b, fractions)
        self.checks += count if blocked < 0 else blocked + 1
        if blocked >= 0 or self.fields is None:
            return blocked < 0
        # occupancy: the end alone (a blocked extension usually fails there), then every other state in one batch
        # (a query per call costs far more than a state)
        states = q_a + fractions[:, None] * (q_b - q_a)
        return self.fields(states[0]) and (count == 1 or bool(self.fields.many(states[1:]).all()))
