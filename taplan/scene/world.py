"""Signed distances, witness points and distance Jacobians between the robot, itself and a scene, in batch.

Pairs: robot body vs robot body (not allowed, :mod:`taplan.scene.robot_bodies`), robot body vs obstacle, attached
object vs obstacle and vs robot bodies it may not touch. Robot-robot distances are closed-form (capsules);
anything involving an obstacle or an attached object goes through coal (GJK/EPA with signed distance; meshes
report 0 in contact). A broad phase skips pairs whose bounding spheres are farther apart than ``cutoff``, so a
scene of 50 obstacles costs the pairs near the robot, not 50 times one obstacle.

The Jacobian of a distance ``d = n · (p_a − p_b)`` with the unit normal ``n`` (from b to a) and the witness points
carried by their links is ``∂d/∂q = n · (J_a(p_a) − J_b(p_b))``, with the point Jacobian
``J(p) = J_v + [ω]×(p − o_joint)`` from pinocchio's joint Jacobians (LOCAL_WORLD_ALIGNED).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from taplan.errors import CollisionError, InvalidInputError
from taplan.scene.engine import KERNEL_LOCK, segment_parameters, shape_code, shape_size, solid_pairs
from taplan.scene.robot_bodies import Body, allowed_pairs, robot_bodies
from taplan.scene.scene import Scene
from taplan.scene.shapes import Box, Capsule, Cylinder, HalfSpace, Sphere

if TYPE_CHECKING:
    from taplan.robot import Robot

__all__ = ["CollisionWorld", "Distances"]


@dataclass(frozen=True)
class Distances:
    """Distances of the active pairs within the cutoff.

    Attributes:
        pairs: ``(robot body or attached object, other body or obstacle)`` names.
        distance: Signed distances [m], negative = penetration depth. Shape (P,).
        point_a: Witness points on the first member [m], root frame. Shape (P, 3).
        point_b: Witness points on the second [m]. Shape (P, 3).
        normal: Unit vectors from b to a (the direction that increases the distance). Shape (P, 3).
        jacobian: ``∂distance/∂q`` [m/rad]. Shape (P, nv), or None when not asked for.
        travel: Per pair, reach coefficients [m/rad]: between two configurations on a straight joint-space segment
            the pair's distance changes by at most ``travel @ |Δq|``. Shape (P, nv).
    """

    pairs: tuple[tuple[str, str], ...]
    distance: np.ndarray
    point_a: np.ndarray
    point_b: np.ndarray
    normal: np.ndarray
    jacobian: np.ndarray | None
    travel: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.pairs)

    def closest(self) -> tuple[float, tuple[str, str]]:
        """The smallest distance [m] and its pair (inf and ("", "") when empty)."""
        if not self.pairs:
            return math.inf, ("", "")
        k = int(np.argmin(self.distance))
        return float(self.distance[k]), self.pairs[k]


@dataclass(frozen=True)
class PairDistances:
    """Distances of named pairs at N configurations (:meth:`CollisionWorld.pair_distances`): ``pairs`` (P names),
    ``distance`` (N, P) [m] (exact, or a lower bound beyond the caller's ``bound_beyond``), ``travel`` (P, nv) the
    pairs' reach rows [m/rad] (:class:`Distances`)."""

    pairs: tuple[tuple[str, str], ...]
    distance: np.ndarray
    travel: np.ndarray


@dataclass(frozen=True)
class _Pairs:
    """Pairs of one kind, before they are joined: names, distances, witness points, normals, the joints carrying
    each member (0: fixed) and the travel rows; where a member is a robot body (its index in ``body_a``/``body_b``,
    -1: not a body) the witness's parameter on that body's segment (``s_a``/``s_b``), from which its Jacobian row
    follows from the segment end points' Jacobians (None: from the witness point and the joint Jacobians)."""

    names: list[tuple[str, str]]
    distance: np.ndarray
    point_a: np.ndarray
    point_b: np.ndarray
    normal: np.ndarray
    owner_a: np.ndarray
    owner_b: np.ndarray
    travel: np.ndarray
    body_a: np.ndarray | None = None
    s_a: np.ndarray | None = None
    body_b: np.ndarray | None = None
    s_b: np.ndarray | None = None


class _Item:
    """An obstacle or attached object with its coal geometry and bounding sphere."""

    def __init__(self, name: str, shape: Any, pose: np.ndarray, frame: int = -1, touch: tuple[str, ...] = ()) -> None:
        import coal

        self.name = name
        self.geometry = shape.to_coal()
        self.pose = pose  # T_root_obstacle, or T_frame_object when attached
        self.frame = frame
        self.touch = set(touch)
        self.radius = shape.bounding_radius()
        self.halfspace = isinstance(shape, HalfSpace)
        self.transform = coal.Transform3s(pose[:3, :3], pose[:3, 3])
        self.center = pose[:3, 3]  # where it is now [m], root frame (attached: updated per configuration)
        self.reach = np.zeros(0)  # attached objects: per joint, how far it can be from the joint [m]
        # the engine's closed form of the shape (-1: none, a mesh), its sizes and its containing capsule
        self.kind = shape_code(shape)
        self.size = np.array(shape_size(shape), dtype=float)
        self.core = float(getattr(shape, "radius", 0.0))
        self.capsule = _containing_capsule(shape)


class CollisionWorld:
    """The robot, its allowed pairs and a scene, evaluated at configurations.

    Args:
        robot: The robot.
        scene: Obstacles and attached objects (changes are picked up through ``scene.version``); None: self only.
        margin: Default clearance [m] for :meth:`in_collision` and :meth:`check_configuration`.
        self_collision: Include robot-robot pairs.
        engine: Evaluate batches (:meth:`distances_many`, :meth:`distance_matrix`) with the batched closed-form
            engine (:mod:`taplan.scene.engine`) where the scene allows; False: coal for every obstacle pair.
        gripper: The grippers' opening when known (0 closed .. 1 open, "open", "closed", per hand as a mapping;
            None: unknown, the fingers' bodies cover the whole range); see :meth:`set_gripper`.
    """

    def __init__(
        self,
        robot: Robot,
        scene: Scene | None = None,
        *,
        margin: float = 0.0,
        self_collision: bool = True,
        engine: bool = True,
        gripper: object = None,
    ):
        import coal

        self._coal = coal
        if not (isinstance(margin, (int, float)) and math.isfinite(margin) and margin >= 0):
            raise InvalidInputError("margin", margin, "a clearance >= 0 [m]")
        if scene is not None and not isinstance(scene, Scene):
            hint = " (load a file with taplan.scene.load_scene)" if isinstance(scene, (str, bytes)) else ""
            raise InvalidInputError("scene", scene, f"a taplan.scene.Scene or None{hint}")
        self.robot = robot
        self.scene = scene if scene is not None else Scene()
        self.scene.bind(robot)  # attached frames and touch bodies checked now and whenever one is attached
        self.margin = float(margin)
        self.model = robot.model
        self.data = robot.model.createData()
        self._self_collision = self_collision
        self._use_bodies(robot_bodies(robot, gripper))
        self._version = -1
        self._items: list[_Item] = []
        self._request = coal.DistanceRequest()
        self._request.enable_signed_distance = True
        # penetration depths of closed-form pairs: to the closed forms' accuracy (as the engine), not GJK's 1e-6 m
        self._depth_request = coal.DistanceRequest()
        self._depth_request.enable_signed_distance = True
        self._depth_request.gjk_tolerance = 1e-12
        self._depth_request.epa_tolerance = 1e-12
        self.use_engine = bool(engine)
        self._engine: Any = None

    def set_gripper(self, gripper: object) -> None:
        """Use the fingers' bodies for a known gripper opening (see :func:`~taplan.scene.robot_bodies`), or None for
        the conservative ones; e.g. from the measured gripper position before each plan or stream segment."""
        self._use_bodies(robot_bodies(self.robot, gripper))
        self._version = -1  # attached objects' touch sets and reach follow the bodies
        self._engine = None  # the batched engine holds the bodies: rebuilt on its next use

    def _use_bodies(self, bodies: list[Body]) -> None:
        coal = self._coal
        robot, self_collision = self.robot, self._self_collision
        self.bodies: list[Body] = bodies
        self.allowed = allowed_pairs(robot, self.bodies)
        self.self_pairs = [
            (i, j)
            for i in range(len(self.bodies))
            for j in range(i + 1, len(self.bodies))
            if self_collision and frozenset((self.bodies[i].name, self.bodies[j].name)) not in self.allowed
        ]
        self._self_index = (
            np.array([i for i, _ in self.self_pairs], dtype=int),
            np.array([j for _, j in self.self_pairs], dtype=int),
        )
        self._radius = np.array([b.radius for b in self.bodies])
        self._body_joint = np.array([b.joint for b in self.bodies], dtype=int)
        self._body_start = np.array([b.start for b in self.bodies], dtype=float).reshape(-1, 3)
        self._body_end = np.array([b.end for b in self.bodies], dtype=float).reshape(-1, 3)
        self._self_names = [(self.bodies[i].name, self.bodies[j].name) for i, j in self.self_pairs]
        # bodies fixed to the root never move relative to an obstacle: a plan cannot change those distances
        self._movers = np.array([k for k, b in enumerate(self.bodies) if b.joint != 0], dtype=int)
        # per joint: the velocity columns of the joints that move it (its chain), for WORLD-frame Jacobians
        self._support = np.zeros((self.model.njoints, self.model.nv))
        for j in range(1, self.model.njoints):
            for k in self.model.supports[j]:
                if k > 0:
                    self._support[
                        j, self.model.joints[k].idx_v : self.model.joints[k].idx_v + self.model.joints[k].nv
                    ] = 1
        self._body_geometry = []
        for b in self.bodies:
            length = float(np.linalg.norm(b.end - b.start))
            geometry = coal.Capsule(b.radius, length) if length > 1e-9 else coal.Sphere(b.radius)
            self._body_geometry.append((geometry, _segment_frame(b.start, b.end)))
        self.reach = self._reach()
        i_idx, j_idx = self._self_index
        self._self_constants = (  # per self pair: radii, travel rows and the joints carrying its members
            self._radius[i_idx],
            self._radius[j_idx],
            self._body_reach[i_idx] + self._body_reach[j_idx],
            self._body_joint[i_idx],
            self._body_joint[j_idx],
        )
        self._kernel: Any = False  # the compiled end point kernel of these bodies: looked up on first use

    # ----------------------------------------------------------------------------------------------- helpers
    def _chain_reach(self, joint: int, extent: float) -> np.ndarray:
        """Per joint, an upper bound [m] on the distance from its axis origin to a point within ``extent`` of the
        origin of ``joint``'s frame (triangle inequality along the chain); zero for joints that do not move it."""
        model = self.model
        row = np.zeros(model.nv)
        along = extent
        j = joint
        while j > 0:
            row[model.joints[j].idx_v] = along
            along += float(np.linalg.norm(model.jointPlacements[j].translation))
            j = model.parents[j]
        return row

    def _reach(self) -> np.ndarray:
        """Per joint, an upper bound [m] on the distance from its origin to any body point it moves."""
        self._body_reach = np.array(
            [
                self._chain_reach(b.joint, max(np.linalg.norm(b.start), np.linalg.norm(b.end)) + b.radius)
                for b in self.bodies
            ]
        ).reshape(len(self.bodies), self.model.nv)
        return self._body_reach.max(axis=0) if len(self.bodies) else np.zeros(self.model.nv)

    def _refresh(self) -> None:
        if self.scene.version == self._version:
            return
        obstacles = list(self.scene.obstacles.values())
        # shapes that answer capsule distances themselves (occupancy voxels) stay out of coal
        self._fields = [o for o in obstacles if hasattr(o.shape, "capsule_distances")]
        self._items = [_Item(o.name, o.shape, o.pose) for o in obstacles if not hasattr(o.shape, "capsule_distances")]
        self._item_center = np.array([item.pose[:3, 3] for item in self._items]).reshape(-1, 3)
        self._item_normal = np.array([item.pose[:3, 2] for item in self._items]).reshape(-1, 3)
        self._item_radius = np.array([item.radius for item in self._items])
        # each item's rotation and local half extents: boxes bound capsules far tighter than bounding spheres
        self._item_rotation = np.array([item.pose[:3, :3] for item in self._items]).reshape(-1, 3, 3)
        self._item_half = np.array(
            [
                np.asarray(o.shape.size, float) / 2 if isinstance(o.shape, Box) else np.full(3, item.radius)
                for o, item in zip(
                    [o for o in obstacles if not hasattr(o.shape, "capsule_distances")], self._items, strict=True
                )
            ]
        ).reshape(-1, 3)
        solids = [o.shape for o in obstacles if not hasattr(o.shape, "capsule_distances")]
        # closed forms of the solid items (engine codes; -1: coal, e.g. meshes) and their sizes for the solvers
        self._item_kind = np.array([shape_code(shape) for shape in solids], dtype=int)
        self._item_size = np.array([shape_size(shape) for shape in solids], dtype=float).reshape(-1, 3)
        self._item_core = np.array([getattr(shape, "radius", 0.0) for shape in solids], dtype=float)
        self._half_index = np.array([k for k, item in enumerate(self._items) if item.halfspace], dtype=int)
        self._solid_index = np.array([k for k, item in enumerate(self._items) if not item.halfspace], dtype=int)
        for item in self._items:
            item.center = item.pose[:3, 3]
        movers = [self.bodies[k].name for k in self._movers]
        self._obstacle_names = [[(body, item.name) for body in movers] for item in self._items]
        self._attached = []
        for a in self.scene.attached.values():
            frame = self.robot.frame_id(a.frame)
            item = _Item(a.name, a.shape, a.pose, frame, a.touch)
            parent = self.model.frames[frame].parentJoint
            item.touch |= {b.name for b in self.bodies if b.joint == parent}
            self._attached.append(item)
            placement = self.model.frames[frame].placement.translation
            extent = float(np.linalg.norm(placement) + np.linalg.norm(a.pose[:3, 3]) + a.shape.bounding_radius())
            item.reach = self._chain_reach(parent, extent)
            self.reach = np.maximum(self.reach, item.reach)
        self._version = self.scene.version

    def _configuration(self, q: npt.ArrayLike, name: str = "q") -> np.ndarray:
        return self.robot.check_configuration(q, name)

    # -------------------------------------------------------------------------------------------------- API
    def distances(
        self, q: npt.ArrayLike, *, cutoff: float = math.inf, jacobian: bool = True, bound_beyond: float = math.inf
    ) -> Distances:
        """Every active pair whose distance may be <= ``cutoff`` [m] (broad phase by bounding spheres).

        Distances are exact, except robot-obstacle pairs whose bounding spheres are farther apart than
        ``bound_beyond`` [m]: those report that gap, a lower bound of their distance (enough for certificates,
        which only need lower bounds, and much cheaper than a coal query).
        """
        return self._distances(q, cutoff, jacobian, bound_beyond)

    def _distances(
        self, q: npt.ArrayLike, cutoff: float, jacobian: bool, bound_beyond: float, self_pairs: bool = True
    ) -> Distances:
        """:meth:`distances`; ``self_pairs=False`` leaves the robot-robot pairs out."""
        q = self._configuration(q)
        self._refresh()
        model, data = self.model, self.data
        kernel = self._end_point_kernel()
        attached = bool(self._attached_items())
        JE = None
        if kernel is not None:  # the bodies' end points (and their Jacobians) in one compiled call
            function, q_in, e_out, j_out = kernel
            with KERNEL_LOCK:
                q_in[:] = q
                function()
                points = e_out.reshape(-1, 2, 3).copy()
                if jacobian:
                    JE = j_out.reshape(model.nv, -1, 2, 3).transpose(1, 2, 3, 0).copy()  # (B, 2, 3, nv)
            starts, ends = points[:, 0], points[:, 1]
        if kernel is None or attached:  # attached objects ride on frames: pinocchio's placements
            if jacobian:
                pin.computeJointJacobians(model, data, q)  # WORLD-frame columns of every joint in data.J
            else:
                pin.forwardKinematics(model, data, q)
            pin.updateFramePlacements(model, data)
        if kernel is None:
            rotation = np.array([data.oMi[j].rotation for j in self._body_joint.tolist()])  # (B, 3, 3)
            origin = np.array([data.oMi[j].translation for j in self._body_joint.tolist()])  # (B, 3)
            starts = np.einsum("bij,bj->bi", rotation, self._body_start) + origin
            ends = np.einsum("bij,bj->bi", rotation, self._body_end) + origin
        parts: list[_Pairs] = []
        if self.self_pairs and self_pairs:
            parts += self._self_distances(starts[None], ends[None], cutoff)
        if self._items:
            parts.append(self._obstacle_distances(starts, ends, cutoff, bound_beyond))
        parts += self._field_distances(starts, ends, cutoff, bound_beyond)
        if attached:
            parts.append(self._attached_distances(q, starts, ends, cutoff, bound_beyond))
        J = (
            np.asarray(data.J).reshape(6, model.nv) if jacobian and (kernel is None or attached) else None
        )  # nv = 1: 1-D
        return self._joined(parts, J, JE)

    def _end_point_kernel(self) -> Any:
        """The compiled kernel ``q -> body end points, their Jacobians`` (:mod:`taplan.scene.engine`), or None
        (the engine disabled, or no C compiler: pinocchio then)."""
        if not self.use_engine:
            return None
        if self._kernel is False:
            from taplan.scene.engine import _native_kernel

            self._kernel = _native_kernel(self)
        return self._kernel

    def distances_many(self, configurations: npt.ArrayLike, *, cutoff: float) -> list[Distances]:
        """:meth:`distances` (with Jacobians, exact) at several configurations (N, nq) in one batch: the same
        pairs and numbers, with the closed-form parts vectorised over the configurations. Scenes with attached
        objects are evaluated one configuration at a time."""
        Q = np.asarray(configurations, dtype=float)
        if Q.ndim != 2 or Q.shape[1] != self.model.nq:
            raise InvalidInputError("configurations", f"shape {Q.shape}", f"(N, {self.model.nq})")
        self._refresh()
        if self._attached_items() or not np.all(np.isfinite(Q)):
            return [self.distances(q, cutoff=cutoff) for q in Q]
        batch = self.jacobian_batch(Q, cutoff=cutoff)
        if batch is not None:
            return [self._from_batch(batch, n, cutoff) for n in range(len(Q))]
        model, data = self.model, self.data
        joints = self._body_joint.tolist()
        N, B = len(Q), len(self.bodies)
        rotation = np.empty((N, B, 3, 3))
        origin = np.empty((N, B, 3))
        jacobians = np.empty((N, 6, model.nv))
        for n, q in enumerate(Q):
            pin.computeJointJacobians(model, data, q)
            rotation[n] = [data.oMi[j].rotation for j in joints]
            origin[n] = [data.oMi[j].translation for j in joints]
            jacobians[n] = data.J
        starts = np.einsum("nbij,bj->nbi", rotation, self._body_start) + origin
        ends = np.einsum("nbij,bj->nbi", rotation, self._body_end) + origin
        parts: list[list[_Pairs]] = [[] for _ in range(N)]
        if self.self_pairs:
            for n, part in enumerate(self._self_distances(starts, ends, cutoff)):
                parts[n].append(part)
        for n in range(N) if self._items else ():
            parts[n].append(self._obstacle_distances(starts[n], ends[n], cutoff, math.inf))
        for n in range(N) if self._fields else ():
            parts[n] += self._field_distances(starts[n], ends[n], cutoff, math.inf)
        return [self._joined(parts[n], jacobians[n]) for n in range(N)]

    def jacobian_batch(self, configurations: npt.ArrayLike, *, cutoff: float) -> Any:
        """The engine's :class:`~taplan.scene.engine.BatchDistances` at N configurations (N, nq) with the Jacobian
        rows of the pairs within ``cutoff`` [m] (the other rows zero): :meth:`distances_many` as arrays, without a
        :class:`Distances` per configuration; attached objects' pairs after the engine's (coal per configuration,
        bounded by spheres beyond the cutoff). None without the engine or with non-finite configurations. Pairs
        beyond the cutoff may report a lower bound of their distance (still beyond the cutoff) instead of the
        distance."""
        Q = np.asarray(configurations, dtype=float)
        if Q.ndim != 2 or Q.shape[1] != self.model.nq:
            raise InvalidInputError("configurations", f"shape {Q.shape}", f"(N, {self.model.nq})")
        self._refresh()
        engine = self.engine()
        if engine is None or not np.all(np.isfinite(Q)):
            return None
        # pairs whose bounding spheres are farther apart than the cutoff report that gap (a lower bound, beyond the
        # cutoff: left out like every pair beyond it) without the exact query
        batch = engine.evaluate(Q, jacobian=True, jacobian_within=cutoff, bound_beyond=cutoff)
        return self._with_attached_rows(batch, Q, cutoff) if self._attached_items() else batch

    def engine(self) -> Any:
        """The batched distance engine for the current scene (:class:`~taplan.scene.engine.DistanceEngine`), or
        None when it is disabled or the scene has obstacles without a closed form (meshes, occupancy)."""
        from taplan.scene.engine import DistanceEngine, supports

        self._refresh()
        if not self.use_engine or not supports(self):
            return None
        if self._engine is None:
            self._engine = DistanceEngine(self)
        return self._engine

    def pair_distances(
        self,
        configurations: npt.ArrayLike,
        pairs: tuple[tuple[str, str], ...] | None = None,
        *,
        bound_beyond: float = math.inf,
    ) -> PairDistances | None:
        """The distances of the named ``pairs`` (as :meth:`distance_matrix` names them; None: every pair) at N
        configurations (N, nq), as :meth:`distance_matrix` reports them (to rounding), without the witness points
        and normals and without evaluating the other pairs: 15-50 % cheaper than :meth:`distance_matrix` for every
        pair, and a certificate's later levels need only the few pairs not yet certified. Attached objects' pairs
        come from :meth:`_attached_many` (only when one is asked for). None where only :meth:`distance_matrix`
        answers: no engine, non-finite configurations, a pair that is not the world's."""
        Q = np.asarray(configurations, dtype=float)
        if Q.ndim != 2 or Q.shape[1] != self.model.nq:
            raise InvalidInputError("configurations", f"shape {Q.shape}", f"(N, {self.model.nq})")
        engine = self.engine()
        if engine is None or not np.all(np.isfinite(Q)):
            return None
        names, travel, _, _ = engine.pair_columns()
        if self._attached_items():
            return self._pair_distances_attached(Q, pairs, bound_beyond)
        if pairs is None:
            every = engine.distances_of(Q, np.arange(len(names)), bound_beyond=bound_beyond)
            return PairDistances(names, every, travel)
        columns = engine.columns_of(tuple(pairs))
        if columns is None:
            return None
        distance = engine.distances_of(Q, columns, bound_beyond=bound_beyond)
        return PairDistances(tuple(pairs), distance, travel[columns])

    def _pair_distances_attached(
        self, Q: np.ndarray, pairs: tuple[tuple[str, str], ...] | None, bound_beyond: float
    ) -> PairDistances | None:
        """:meth:`pair_distances` with attached objects: the engine's pairs from the engine, the objects' from
        :meth:`_attached_many` (all of theirs at once, as :meth:`distance_matrix` has them; only when one is
        asked for), in the asked order (None: the engine's pairs, then the objects')."""
        engine = self.engine()
        names, travel, _, _ = engine.pair_columns()
        if pairs is None:
            E, _ = engine.segments(Q, jacobian=False)
            found = self._attached_many(Q, E, bound_beyond, False)
            every = engine.distances_of(Q, np.arange(len(names)), bound_beyond=bound_beyond)
            return PairDistances(names + tuple(found[0]), np.hstack([every, found[1]]), np.vstack([travel, found[7]]))
        owners = {att.name for att in self._attached_items()}
        wanted = tuple(pairs)
        own = np.array([pair[0] not in owners for pair in wanted], dtype=bool)
        columns = engine.columns_of(tuple(pair for pair, mine in zip(wanted, own, strict=True) if mine))
        if columns is None:
            return None
        distance = np.empty((len(Q), len(wanted)))
        rows = np.empty((len(wanted), self.model.nv))
        distance[:, own] = engine.distances_of(Q, columns, bound_beyond=bound_beyond)
        rows[own] = travel[columns]
        if not own.all():
            E, _ = engine.segments(Q, jacobian=False)
            objects = np.flatnonzero(~own)
            found = self._attached_many(Q, E, bound_beyond, False, only={wanted[k] for k in objects.tolist()})
            index = {pair: k for k, pair in enumerate(found[0])}
            column = [index.get(wanted[k], -1) for k in objects.tolist()]
            if -1 in column:
                return None
            distance[:, objects] = found[1][:, column]
            rows[objects] = found[7][column]
        return PairDistances(wanted, distance, rows)

    def distance_matrix(self, configurations: npt.ArrayLike, *, bound_beyond: float = math.inf) -> Any:
        """Every pair (no cutoff) at N configurations (N, nq) as one :class:`~taplan.scene.engine.BatchDistances`
        without Jacobians: the engine's batch where it applies (scenes without attached objects), else the pairs of
        :meth:`distances` per configuration aligned by name (a pair missing at a configuration: +inf). Robot-obstacle
        pairs whose bounding spheres are farther apart than ``bound_beyond`` [m] report that gap (a lower bound)."""
        from taplan.scene.engine import BatchDistances

        Q = np.asarray(configurations, dtype=float)
        if Q.ndim != 2 or Q.shape[1] != self.model.nq:
            raise InvalidInputError("configurations", f"shape {Q.shape}", f"(N, {self.model.nq})")
        engine = self.engine()
        if engine is not None and np.all(np.isfinite(Q)):
            batch = engine.evaluate(Q, jacobian=False, bound_beyond=bound_beyond)
            return self._with_attached(batch, Q, bound_beyond) if self._attached_items() else batch
        each = [self.distances(q, jacobian=False, bound_beyond=bound_beyond) for q in Q]
        index: dict[tuple[str, str], int] = {}
        for d in each:
            for pair in d.pairs:
                index.setdefault(pair, len(index))
        N, P, nv = len(Q), len(index), self.model.nv
        distance = np.full((N, P), np.inf)
        points = np.zeros((N, P, 3))
        travel = np.zeros((P, nv))
        for n, d in enumerate(each):
            columns = np.array([index[pair] for pair in d.pairs], dtype=int)
            distance[n, columns] = d.distance
            assert d.travel is not None
            travel[columns] = d.travel
        owners = np.zeros(P, dtype=int)
        return BatchDistances(tuple(index), distance, points, points, points, None, travel, owners, owners)

    def _with_attached(self, batch: Any, Q: np.ndarray, bound_beyond: float) -> Any:
        """The engine's batch plus the attached objects' pairs (:meth:`_attached_many`)."""
        E, _ = self.engine().segments(Q, jacobian=False)  # the bodies' end points, as the engine's batch has them
        names, d, pa, pb, normal, owner_a, owner_b, travel, _ = self._attached_many(Q, E, bound_beyond, False)
        return _joined(batch, names, d, pa, pb, normal, None, travel, owner_a, owner_b)

    def _with_attached_rows(self, batch: Any, Q: np.ndarray, cutoff: float) -> Any:
        """The engine's batch (with Jacobians) plus the attached objects' pairs (:meth:`_attached_many`, bounded
        beyond ``cutoff``) and their Jacobian rows within ``cutoff``: :meth:`distances_many`'s pairs without a
        :class:`Distances` per configuration, and the robot's own pairs batched."""
        E, _ = self.engine().segments(Q, jacobian=False)  # the bodies' end points, as the engine's batch has them
        names, distance, point_a, point_b, normal, owner_a, owner_b, travel, J = self._attached_many(Q, E, cutoff, True)
        N, A, nv = len(Q), len(names), self.model.nv
        # the rows of :meth:`_part_rows` for every configuration at once: n · (v + ω × p) of each moving member
        rows = np.zeros((N, A, nv))
        for owner, point, sign in ((owner_a, point_a, 1.0), (owner_b, point_b, -1.0)):
            moving = owner > 0
            if np.any(moving):
                n_, p_ = normal[:, moving], point[:, moving]
                row = n_ @ J[:, :3] + np.cross(p_, n_) @ J[:, 3:]
                rows[:, moving] += sign * row * self._support[owner[moving]][None]
        rows[distance > cutoff] = 0.0  # as the engine's: rows only within the cutoff
        return _joined(batch, names, distance, point_a, point_b, normal, rows, travel, owner_a, owner_b)

    def _from_batch(self, batch: Any, n: int, cutoff: float) -> Distances:
        """Configuration ``n`` of an engine batch as :class:`Distances` (pairs within ``cutoff``, the world's order)."""
        keep = np.flatnonzero((batch.distance[n] <= cutoff) & np.isfinite(batch.distance[n]))
        return Distances(
            tuple(batch.pairs[k] for k in keep),
            batch.distance[n, keep],
            batch.point_a[n, keep],
            batch.point_b[n, keep],
            batch.normal[n, keep],
            None if batch.jacobian is None else batch.jacobian[n, keep],
            batch.travel[keep],
        )

    def _joined(self, parts: list[_Pairs], J: np.ndarray | None, JE: np.ndarray | None = None) -> Distances:
        """One :class:`Distances` from the parts, with ``∂d/∂q = n · (J_a(p_a) − J_b(p_b))``: for a robot body's
        witness at parameter ``s`` on its segment from the end points' Jacobians ``JE`` (B, 2, 3, nv),
        ``n · ((1 − s) J(e0) + s J(e1))`` (its offset ``r n`` from the axis adds ``n · (ω × r n) = 0``); else from
        the WORLD-frame joint Jacobians ``J`` (6, nv) of the configuration (a point's velocity is ``v + ω × p``).
        Both None: no Jacobians."""
        nv = self.model.nv
        parts = [part for part in parts if len(part.names)]
        if not parts:
            empty = np.zeros((0, 3))
            rows = None if J is None and JE is None else np.zeros((0, nv))
            return Distances((), np.zeros(0), empty, empty, empty, rows, np.zeros((0, nv)))

        def column(field: str) -> np.ndarray:
            values = [getattr(part, field) for part in parts]
            return values[0] if len(values) == 1 else np.concatenate(values)

        names = tuple(itertools.chain.from_iterable(part.names for part in parts))
        distance, travel = column("distance"), column("travel")
        point_a, point_b, normal = column("point_a"), column("point_b"), column("normal")
        rows = None
        if J is not None or JE is not None:
            rows = np.concatenate([self._part_rows(part, J, JE) for part in parts])
        return Distances(names, distance, point_a, point_b, normal, rows, travel)

    def _part_rows(self, part: _Pairs, J: np.ndarray | None, JE: np.ndarray | None) -> np.ndarray:
        """The Jacobian rows of one part (see :meth:`_joined`)."""
        nv, count = self.model.nv, len(part.names)
        if JE is not None and part.body_a is not None:
            # robot bodies' witnesses: each row is n · Σ weight · J(end point) over both members' segment ends
            body_a, body_b, s_a, s_b = part.body_a, part.body_b, part.s_a, part.s_b
            on_a, on_b = body_a >= 0, body_b >= 0
            ends = np.stack([2 * body_a, 2 * body_a + 1, 2 * body_b, 2 * body_b + 1], axis=1)
            weight = np.stack([(1.0 - s_a) * on_a, s_a * on_a, (s_b - 1.0) * on_b, -s_b * on_b], axis=1)
            terms = (weight[:, :, None] * part.normal[:, None, :]).reshape(count, 1, 12)
            gathered = JE.reshape(-1, 3, nv)[np.maximum(ends, 0)].reshape(count, 12, nv)
            return (terms @ gathered)[:, 0]
        # from the joint Jacobians: attached objects' witnesses, or no end-point Jacobians
        assert J is not None, "members that are not robot bodies need the joint Jacobians"
        rows = np.zeros((count, nv))
        for owner, point, sign in ((part.owner_a, part.point_a, 1.0), (part.owner_b, part.point_b, -1.0)):
            moving = owner > 0
            if np.any(moving):
                n = part.normal[moving]
                row = n @ J[:3] + np.cross(point[moving], n) @ J[3:]
                rows[moving] += sign * row * self._support[owner[moving]]
        return rows

    def _self_distances(self, starts: np.ndarray, ends: np.ndarray, cutoff: float) -> list[_Pairs]:
        """Robot body pairs (capsules) in closed form, for N configurations (``starts``, ``ends``: (N, B, 3))."""
        i_idx, j_idx = self._self_index
        N, S = len(starts), len(i_idx)
        a0, a1 = starts[:, i_idx].reshape(-1, 3), ends[:, i_idx].reshape(-1, 3)
        b0, b1 = starts[:, j_idx].reshape(-1, 3), ends[:, j_idx].reshape(-1, 3)
        s, t = segment_parameters(a0, a1, b0, b1)
        pa, pb = a0 + s[:, None] * (a1 - a0), b0 + t[:, None] * (b1 - b0)
        s, t = s.reshape(N, S), t.reshape(N, S)
        delta = pa - pb
        norm = np.linalg.norm(delta, axis=1)
        r_i, r_j, travel, owner_i, owner_j = self._self_constants
        d = norm.reshape(N, S) - (r_i + r_j)
        normal = np.where(norm[:, None] > 1e-12, delta / np.maximum(norm, 1e-12)[:, None], [0.0, 0.0, 1.0])
        normal = normal.reshape(N, S, 3)
        pa = pa.reshape(N, S, 3) - r_i[:, None] * normal
        pb = pb.reshape(N, S, 3) + r_j[:, None] * normal
        out = []
        for n in range(N):
            if cutoff == math.inf:  # every pair: no gathering
                names = list(self._self_names)
                out.append(
                    _Pairs(names, d[n], pa[n], pb[n], normal[n], owner_i, owner_j, travel, i_idx, s[n], j_idx, t[n])
                )
                continue
            keep = np.flatnonzero(d[n] <= cutoff)
            out.append(
                _Pairs(
                    [self._self_names[k] for k in keep],
                    d[n, keep],
                    pa[n, keep],
                    pb[n, keep],
                    normal[n, keep],
                    owner_i[keep],
                    owner_j[keep],
                    travel[keep],
                    i_idx[keep],
                    s[n, keep],
                    j_idx[keep],
                    t[n, keep],
                )
            )
        return out

    def _obstacle_distances(
        self,
        starts: np.ndarray,
        ends: np.ndarray,
        cutoff: float,
        bound_beyond: float,
    ) -> _Pairs:
        """Moving robot bodies vs static obstacles: half-spaces in closed form, others bounded by their bounding
        spheres and boxes and, when that bound is within ``bound_beyond``, computed exactly: in closed form (boxes,
        spheres, capsules, cylinders: :func:`~taplan.scene.engine.solid_pairs`; with ``use_engine``) or by coal
        (meshes, penetration depths). Item-major order."""
        movers = self._movers
        s0, s1 = starts[movers], ends[movers]  # (Bm, 3)
        radius = self._radius[movers]
        items = self._items
        M, Bm = len(items), len(movers)
        d = np.empty((M, Bm))
        pa = np.empty((M, Bm, 3))
        pb = np.empty((M, Bm, 3))
        n = np.empty((M, Bm, 3))
        along = np.full((M, Bm), 0.5)  # the witness's parameter on the body's segment (bounds: its middle)
        half = self._half_index
        if half.size:
            normal = self._item_normal[half]  # (H, 3)
            h0 = np.einsum("hk,bk->hb", normal, s0) - np.einsum("hk,hk->h", normal, self._item_center[half])[:, None]
            h1 = h0 + np.einsum("hk,bk->hb", normal, s1 - s0)
            low = np.where((h0 <= h1)[:, :, None], s0[None], s1[None])
            gap = np.minimum(h0, h1)
            d[half] = gap - radius[None]
            n[half] = normal[:, None, :]
            pa[half] = low - radius[None, :, None] * normal[:, None, :]
            pb[half] = low - gap[:, :, None] * normal[:, None, :]
            along[half] = np.where(h0 <= h1, 0.0, 1.0)
        solid = self._solid_index
        transforms: dict[int, Any] = {}
        if solid.size:
            center = self._item_center[solid]  # (S, 3)
            # the segments in each item's frame, as rows: Rᵀ (x − c) = (x − c) R
            R = self._item_rotation[solid]
            a0 = (s0[None] - center[:, None, :]) @ R
            a1 = (s1[None] - center[:, None, :]) @ R
            if cutoff < math.inf or bound_beyond < math.inf:
                # the bounds are reported only for pairs beyond bound_beyond: otherwise the cheaper one does
                gap = self._solid_bounds(a0, a1, radius, solid, boxes_only=bound_beyond == math.inf)
                pick = (gap <= cutoff) & (gap <= bound_beyond)
            else:  # every pair exact: no bound needed
                gap = np.full(a0.shape[:2], -math.inf)
                pick = np.ones(a0.shape[:2], dtype=bool)
            d[solid] = gap
            if bound_beyond < math.inf and not pick.all():  # reported bounds' witnesses: middle and centre
                mid = (s0 + s1) / 2
                away = mid[None] - center[:, None, :]
                pa[solid] = mid[None]
                pb[solid] = np.broadcast_to(center[:, None, :], away.shape)
                n[solid] = away / np.maximum(np.linalg.norm(away, axis=2), 1e-12)[:, :, None]
            s_rows, b_cols = np.nonzero(pick)
            m_rows = solid[s_rows]
            closed = self._item_kind[m_rows] >= 0 if self.use_engine else np.zeros(len(m_rows), dtype=bool)
            coal_pairs = [
                (int(i), int(j), self._request) for i, j in zip(m_rows[~closed], b_cols[~closed], strict=True)
            ]
            if closed.any():  # boxes, spheres, capsules, cylinders: closed forms for all these pairs at once
                m, b = m_rows[closed], b_cols[closed]
                e0, e1 = a0[s_rows[closed], b], a1[s_rows[closed], b]
                size, core = self._item_size[m], self._item_core[m]
                s_k, d_k, pa_k, pb_k, n_k, inside = solid_pairs(self._item_kind[m], size, core, e0, e1, radius[b])
                Rt, c = self._item_rotation[m].transpose(0, 2, 1), self._item_center[m]
                d[m, b], along[m, b] = d_k, s_k
                pa[m, b] = (pa_k[:, None, :] @ Rt)[:, 0] + c  # back to the root frame: x R_itemᵀ + c
                pb[m, b] = (pb_k[:, None, :] @ Rt)[:, 0] + c
                n[m, b] = (n_k[:, None, :] @ Rt)[:, 0]
                # the axis touches or enters the solid: a penetration depth, coal's EPA (as the engine does)
                coal_pairs += [(int(i), int(j), self._depth_request) for i, j in zip(m[inside], b[inside], strict=True)]
            for m_k, b_col, request in coal_pairs:
                item, body = items[m_k], int(movers[b_col])
                if body not in transforms:  # the capsule's frame from its end points (any turn about its axis)
                    frame = _segment_frame(s0[b_col], s1[b_col])
                    transforms[body] = self._coal.Transform3s(frame[:3, :3], frame[:3, 3])
                geometry, placement = self._body_geometry[body][0], transforms[body]
                d_k, pa_k, pb_k, n_k = self._pair(item.geometry, item.transform, geometry, placement, request)
                d[m_k, b_col], pa[m_k, b_col], pb[m_k, b_col], n[m_k, b_col] = d_k, pa_k, pb_k, n_k
                along[m_k, b_col] = _parameter(pa_k + radius[b_col] * n_k, s0[b_col], s1[b_col])
        rows, cols = np.nonzero(d <= cutoff)
        table = self._obstacle_names
        names = [table[r][c] for r, c in zip(rows.tolist(), cols.tolist(), strict=True)]
        paired = movers[cols]
        part = _Pairs(
            names,
            d[rows, cols],
            pa[rows, cols],
            pb[rows, cols],
            n[rows, cols],
            self._body_joint[paired],
            np.zeros(len(rows), dtype=int),
            self._body_reach[paired],
            paired,
            along[rows, cols],
            np.full(len(rows), -1),
            np.zeros(len(rows)),
        )
        return part

    def _solid_bounds(
        self, a0: np.ndarray, a1: np.ndarray, radius: np.ndarray, solid: np.ndarray, boxes_only: bool = False
    ) -> np.ndarray:
        """Lower bounds (S, Bm) [m] of the moving capsules' (segments ``a0``-``a1`` in each item's frame, (S, Bm, 3))
        distances to the solid items: the segment's distance to the item's centre minus both bounding radii, and
        where positive the gap between the capsule's box and the item's box (both in the item's frame).
        ``boxes_only``: the boxes' gap alone (a weaker bound, enough to skip pairs beyond a cutoff)."""
        h = self._item_half[solid][:, None, :]
        lo = np.minimum(a0, a1) - radius[None, :, None]
        hi = np.maximum(a0, a1) + radius[None, :, None]
        apart = np.linalg.norm(np.maximum(np.maximum(lo - h, -h - hi), 0.0), axis=2)
        if boxes_only:
            return apart
        axis = a1 - a0
        length2 = np.sum(axis * axis, axis=2)
        t = -np.sum(a0 * axis, axis=2) / np.maximum(length2, 1e-18)
        t = np.clip(np.where(length2 < 1e-18, 0.0, t), 0.0, 1.0)
        nearest = a0 + t[:, :, None] * axis  # the segment's point nearest the item's centre (its origin)
        gap = np.linalg.norm(nearest, axis=2) - radius[None] - self._item_radius[solid][:, None]
        return np.where(apart > 0.0, np.maximum(gap, apart), gap)  # the box bound is one of positive distances only

    def _field_distances(
        self, starts: np.ndarray, ends: np.ndarray, cutoff: float, bound_beyond: float
    ) -> list[_Pairs]:
        """Moving bodies vs obstacles that answer capsule distances themselves (one pair per body: the nearest
        part), in the obstacle's frame and back."""
        movers = self._movers
        out = []
        for o in self._fields:
            R, t = o.pose[:3, :3], o.pose[:3, 3]
            d, pa, pb, n = o.shape.capsule_distances(
                (starts[movers] - t) @ R, (ends[movers] - t) @ R, self._radius[movers], cutoff, bound_beyond
            )
            keep = np.flatnonzero((d <= cutoff) & np.isfinite(d))
            paired = movers[keep]
            # the witness's parameter on the body's axis (its point on the axis is pa + r n), obstacle frame
            r = self._radius[paired]
            on_axis = pa[keep] + r[:, None] * n[keep]
            along = _parameter(on_axis, (starts[paired] - t) @ R, (ends[paired] - t) @ R)
            out.append(
                _Pairs(
                    [(self.bodies[k].name, o.name) for k in paired],
                    d[keep],
                    pa[keep] @ R.T + t,
                    pb[keep] @ R.T + t,
                    n[keep] @ R.T,
                    self._body_joint[paired],
                    np.zeros(len(keep), dtype=int),
                    self._body_reach[paired],
                    paired,
                    along,
                    np.full(len(keep), -1),
                    np.zeros(len(keep)),
                )
            )
        return out

    def _attached_many(
        self,
        Q: np.ndarray,
        E: np.ndarray,
        bound_beyond: float,
        jacobians: bool,
        only: set[tuple[str, str]] | None = None,
    ) -> tuple:
        """:meth:`_attached_distances` without a cutoff at N configurations ``Q`` (N, nq) whose body end points
        are ``E`` (N, B, 2, 3), for all configurations at once. With the engine (``use_engine``) an object with a
        closed form (box, sphere, capsule, cylinder) gets its robot body pairs in closed form (the body's capsule
        against the object, in the object's frame: :func:`~taplan.scene.engine.solid_pairs`) and half-spaces by
        its support point; against solid obstacles its containing capsule bounds it (exact for spheres and
        capsules). coal runs only for the pairs those bounds keep within ``bound_beyond`` (and meshes,
        penetrations of a body's axis); the others report their bound. ``only``: these pairs alone (by name; a
        certificate's later levels need a few). Returns the pairs' names, distances (N, A), witness points and
        normals (N, A, 3), owners (A,), travel rows (A, nv) and, with ``jacobians``, the WORLD joint Jacobians
        (N, 6, nv) of the configurations."""
        model, data = self.model, self.data
        N, nv = len(Q), model.nv
        attached = self._attached_items()
        frames = np.empty((N, len(attached), 4, 4))
        J = np.empty((N, 6, nv)) if jacobians else None
        for n, q in enumerate(Q):  # the objects' frames (the bodies' come from their end points)
            if J is not None:
                pin.computeJointJacobians(model, data, q)
                J[n] = np.asarray(data.J).reshape(6, nv)
            else:
                pin.forwardKinematics(model, data, q)
            pin.updateFramePlacements(model, data)
            for a, att in enumerate(attached):
                frames[n, a] = data.oMf[att.frame].homogeneous @ att.pose
        names: list[tuple[str, str]] = []
        columns: list[tuple[np.ndarray, ...]] = []  # per group of pairs: d (N, k), pa, pb, n (N, k, 3)
        owner_a: list[np.ndarray] = []
        owner_b: list[np.ndarray] = []
        travel: list[np.ndarray] = []

        def wanted(att: _Item, other: str) -> bool:
            return only is None or (att.name, other) in only

        for a, att in enumerate(attached):
            parent = model.frames[att.frame].parentJoint
            items = np.array([m for m, item in enumerate(self._items) if wanted(att, item.name)], dtype=int)
            columns.append(self._attached_items_columns(att, frames[:, a], bound_beyond, items))
            for m in items.tolist():
                names.append((att.name, self._items[m].name))
                owner_b.append(np.zeros(1, dtype=int))
                travel.append(att.reach[None])
            listed = np.array(
                [k for k, body in enumerate(self.bodies) if body.name not in att.touch and wanted(att, body.name)],
                dtype=int,
            )
            columns.append(self._attached_bodies_columns(att, frames[:, a], E[:, listed], listed, bound_beyond))
            names += [(att.name, self.bodies[k].name) for k in listed.tolist()]
            owner_b.append(self._body_joint[listed])
            travel.append(att.reach[None] + self._body_reach[listed])
            owner_a.append(np.full(len(items) + len(listed), parent))
            center = frames[:, a, :3, 3]
            fields = [o for o in self._fields if wanted(att, o.name)]
            for o in fields:  # against the object's bounding sphere: a lower bound of its distance
                R, t = o.pose[:3, :3], o.pose[:3, 3]
                local = (center - t) @ R
                fd, fpa, fpb, fn = o.shape.capsule_distances(local, local, np.full(N, att.radius), math.inf)
                columns.append((fd[:, None], (fpa @ R.T + t)[:, None], (fpb @ R.T + t)[:, None], (fn @ R.T)[:, None]))
                names.append((att.name, o.name))
                owner_a.append(np.array([parent]))
                owner_b.append(np.zeros(1, dtype=int))
                travel.append(att.reach[None])
        d, pa, pb, normal = (np.concatenate([c[i] for c in columns], axis=1) for i in range(4))
        return (
            names,
            d,
            pa,
            pb,
            normal,
            np.concatenate(owner_a),
            np.concatenate(owner_b),
            np.concatenate(travel).reshape(len(names), nv),
            J,
        )

    def _attached_bodies_columns(
        self, att: _Item, frames: np.ndarray, E: np.ndarray, listed: np.ndarray, bound_beyond: float
    ) -> tuple[np.ndarray, ...]:
        """The object ``att`` (placed at ``frames`` (N, 4, 4)) against the robot bodies ``listed`` (L,) whose end
        points are ``E`` (N, L, 2, 3): (d (N, L), p_a on the object, p_b on the body, normal from body to object).
        First the object's containing capsule against the bodies' capsules, all pairs at once (exact for spheres
        and capsules); where that lower bound is within ``bound_beyond``, the exact distance: in closed form where
        the engine may and the object has one (the body's capsule against the object in its frame), else coal."""
        N, L = E.shape[:2]
        R, c = frames[:, :3, :3], frames[:, :3, 3]
        radius = np.tile(self._radius[listed], N)
        axis, rounding = att.capsule
        tip = np.repeat(R @ axis, L, axis=0)  # (N L, 3): the object's core segment is c ± tip
        a0, a1 = np.repeat(c, L, axis=0) - tip, np.repeat(c, L, axis=0) + tip
        b0, b1 = E[:, :, 0].reshape(-1, 3), E[:, :, 1].reshape(-1, 3)
        s, t = segment_parameters(a0, a1, b0, b1)
        delta = a0 + s[:, None] * (a1 - a0) - (b0 + t[:, None] * (b1 - b0))
        norm = np.sqrt(np.einsum("ij,ij->i", delta, delta))
        normal = np.where(norm[:, None] > 1e-12, delta / np.maximum(norm, 1e-12)[:, None], [0.0, 0.0, 1.0])
        d = norm - rounding - radius
        pa = a0 + s[:, None] * (a1 - a0) - rounding * normal
        pb = b0 + t[:, None] * (b1 - b0) + radius[:, None] * normal
        exact: list[tuple[int, Any]] = []  # (row, coal request)
        if att.kind not in _ROUNDED or not self.use_engine:
            near = np.flatnonzero(d <= bound_beyond)
            if self.use_engine and att.kind >= 0 and near.size:
                # the bodies' segments in the object's frame, (x − c) R = Rᵀ (x − c); the object as the "obstacle"
                Rn, cn = R[near // L], c[near // L]
                e0 = np.einsum("mk,mkj->mj", b0[near] - cn, Rn)
                e1 = np.einsum("mk,mkj->mj", b1[near] - cn, Rn)
                m = near.size
                _, d_k, pa_k, pb_k, n_k, inside = solid_pairs(
                    np.full(m, att.kind), np.tile(att.size, (m, 1)), np.full(m, att.core), e0, e1, radius[near]
                )
                d[near] = d_k
                pa[near] = np.einsum("mkj,mj->mk", Rn, pb_k) + cn  # the object's witness, back to the root frame
                pb[near] = np.einsum("mkj,mj->mk", Rn, pa_k) + cn  # the body's
                normal[near] = -np.einsum("mkj,mj->mk", Rn, n_k)  # solid_pairs' normal: from the object to the body
                exact = [(int(row), self._depth_request) for row in near[inside]]
            else:
                exact = [(int(row), self._request) for row in near]
        elif self.use_engine:
            # a sphere or capsule is its own containing capsule: exact, but for penetrations of the two axes
            exact = [(int(row), self._depth_request) for row in np.flatnonzero(norm <= 1e-12)]
        for row, request in exact:
            n, col = divmod(row, L)
            frame = _segment_frame(E[n, col, 0], E[n, col, 1])  # the capsule is symmetric about its axis
            placement = self._coal.Transform3s(frame[:3, :3], frame[:3, 3])
            d[row], pa[row], pb[row], normal[row] = self._pair(
                self._body_geometry[int(listed[col])][0], placement, att.geometry, self._placed(frames[n]), request
            )
        return d.reshape(N, L), pa.reshape(N, L, 3), pb.reshape(N, L, 3), normal.reshape(N, L, 3)

    def _attached_items_columns(
        self, att: _Item, frames: np.ndarray, bound_beyond: float, which: np.ndarray
    ) -> tuple[np.ndarray, ...]:
        """The object ``att`` (placed at ``frames`` (N, 4, 4)) against the obstacle items ``which`` (M,): (d (N, M),
        p_a on the object, p_b on the item, normal from item to object). Half-spaces by the object's support point
        where it has a closed form (exact); solids by the object's containing capsule in closed form (exact for
        spheres and capsules) or its bounding sphere, and coal where that bound is within ``bound_beyond``."""
        N, M = len(frames), len(which)
        R, c = frames[:, :3, :3], frames[:, :3, 3]
        d, pa, pb, normal = np.empty((N, M)), np.empty((N, M, 3)), np.empty((N, M, 3)), np.empty((N, M, 3))
        closed = self.use_engine and att.kind >= 0
        for col, m in enumerate(which.tolist()):
            item, request = self._items[m], self._request
            if item.halfspace and closed:
                up = item.pose[:3, 2]  # the half-space's outward normal
                point = c + np.einsum("nkj,nj->nk", R, _support(att, -up @ R))  # the object's deepest point
                d[:, col] = (point - item.center) @ up
                pa[:, col], pb[:, col], normal[:, col] = point, point - d[:, col, None] * up, up
                continue
            if item.halfspace:
                d[:, col] = -np.inf  # no bound for a half-space: always the exact query
            elif closed and self._item_kind[m] >= 0:
                # the object's containing capsule (its core segment along ``axis``, ``rounding``) as the "robot"
                # capsule against the item, in the item's frame: exact when the object is that capsule
                axis, rounding = att.capsule
                Ri, ci = self._item_rotation[m], self._item_center[m]
                tip = np.einsum("nkj,j->nk", R, axis)
                e0, e1 = (c - tip - ci) @ Ri, (c + tip - ci) @ Ri
                _, d_k, pa_k, pb_k, n_k, inside = solid_pairs(
                    np.full(N, self._item_kind[m]),
                    np.tile(self._item_size[m], (N, 1)),
                    np.full(N, self._item_core[m]),
                    e0,
                    e1,
                    np.full(N, rounding),
                )
                d[:, col] = np.where(inside, -np.inf, d_k)
                pa[:, col], pb[:, col], normal[:, col] = pa_k @ Ri.T + ci, pb_k @ Ri.T + ci, n_k @ Ri.T
                if att.kind in _ROUNDED:  # the object is its capsule: exact but for penetrations of its axis
                    request = self._depth_request
                    for n in np.flatnonzero(inside).tolist():
                        d[n, col], pa[n, col], pb[n, col], normal[n, col] = self._pair(
                            item.geometry, item.transform, att.geometry, self._placed(frames[n]), request
                        )
                    continue
            else:
                away = c - item.center
                apart = np.linalg.norm(away, axis=-1)
                unit = away / np.maximum(apart, 1e-12)[:, None]
                d[:, col], normal[:, col] = apart - item.radius - att.radius, unit
                pa[:, col], pb[:, col] = c - att.radius * unit, item.center + item.radius * unit
            for n in np.flatnonzero(d[:, col] <= bound_beyond).tolist():
                d[n, col], pa[n, col], pb[n, col], normal[n, col] = self._pair(
                    item.geometry, item.transform, att.geometry, self._placed(frames[n]), request
                )
        return d, pa, pb, normal

    def _placed(self, frame: np.ndarray) -> Any:
        return self._coal.Transform3s(frame[:3, :3], frame[:3, 3])

    def _attached_distances(
        self, q: np.ndarray, starts: np.ndarray, ends: np.ndarray, cutoff: float, bound_beyond: float = math.inf
    ) -> _Pairs:
        """Attached objects vs obstacles and vs the robot bodies they may not touch at ``q`` (bodies' end points
        ``starts``, ``ends`` (B, 3)): :meth:`_attached_many` for one configuration, the pairs within ``cutoff``;
        pairs whose bound is beyond ``bound_beyond`` report it. (It runs the forward kinematics of ``q`` into
        ``self.data`` again: the same placements, and the joint Jacobians there stay.)"""
        nv = self.model.nv
        E = np.stack([starts, ends], axis=1)[None]
        names, d, pa, pb, normal, owner_a, owner_b, travel, _ = self._attached_many(
            q[None], E, min(bound_beyond, cutoff), False
        )
        keep = np.flatnonzero(d[0] <= cutoff)
        return _Pairs(
            [names[k] for k in keep.tolist()],
            d[0, keep],
            pa[0, keep],
            pb[0, keep],
            normal[0, keep],
            owner_a[keep],
            owner_b[keep],
            travel[keep].reshape(len(keep), nv),
        )

    def _attached_items(self) -> list[_Item]:
        return getattr(self, "_attached", [])

    def _body_transforms(self) -> list[Any]:
        """Each body's coal transform at the configuration held in ``self.data``."""
        return [self._body_transform(k) for k in range(len(self.bodies))]

    def _body_transform(self, k: int) -> Any:
        placement = self.data.oMi[self.bodies[k].joint]
        return self._coal_placement(placement.rotation, placement.translation, k)

    def _coal_placement(self, rotation: np.ndarray, origin: np.ndarray, k: int) -> Any:
        """Body ``k``'s coal transform when its joint is at (``rotation``, ``origin``) in the root frame."""
        local = self._body_geometry[k][1]
        return self._coal.Transform3s(rotation @ local[:3, :3], rotation @ local[:3, 3] + origin)

    def _body_geometry_at(self, k: int, transforms: list[Any]) -> tuple[Any, Any]:
        return self._body_geometry[k][0], transforms[k]

    def _pair(
        self, g1: Any, t1: Any, g2: Any, t2: Any, request: Any = None
    ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """coal distance between object 1 (b) and object 2 (a): (d, p_a, p_b, n from b to a)."""
        from taplan.scene.coal_query import signed_distance

        d, pb, pa, n = signed_distance(self._coal, g1, t1, g2, t2, self._request if request is None else request)
        return d, pa, pb, n

    def min_distance(self, q: npt.ArrayLike) -> tuple[float, tuple[str, str]]:
        """The smallest signed distance [m] over the active pairs, and its pair.

        Branch and bound: robot-obstacle pairs first as lower bounds (bounding spheres and boxes, no coal query);
        only those whose bound is below the smallest exact distance are then queried exactly.
        """
        coarse = self.distances(q, jacobian=False, bound_beyond=-math.inf)
        bounded = {self._items[k].name for k in self._solid_index} | {o.name for o in self._fields}
        bounded |= {a.name for a in self._attached_items()}  # attached objects report bounds beyond it too
        exact = [
            d for (a, b), d in zip(coarse.pairs, coarse.distance, strict=True) if a not in bounded and b not in bounded
        ]
        best = min(exact, default=math.inf)
        if len(coarse.distance) and float(np.min(coarse.distance)) < best:
            # the robot pairs are exact already (the first ones, all of them): only the others again, exactly
            # where their bound is below the best exact distance
            S = len(self.self_pairs)
            k = int(np.argmin(coarse.distance[:S])) if S else -1
            closest_self = (float(coarse.distance[k]), coarse.pairs[k]) if S else (math.inf, ("", ""))
            rest = self._distances(q, math.inf, False, best, self_pairs=False).closest()
            return rest if rest[0] < closest_self[0] else closest_self
        return coarse.closest()

    def in_collision(self, q: npt.ArrayLike, *, margin: float | None = None) -> bool:
        """True when a pair is closer than ``margin`` [m] (default ``self.margin``)."""
        m = self.margin if margin is None else float(margin)
        return self.distances(q, cutoff=m, jacobian=False).closest()[0] < m

    def check_configuration(self, q: npt.ArrayLike, argument: str = "q", *, margin: float | None = None) -> None:
        """Raise :class:`~taplan.errors.CollisionError` naming the pair and its depth [mm] when ``q`` collides."""
        m = self.margin if margin is None else float(margin)
        d, pair = self.distances(self._configuration(q, argument), cutoff=m, jacobian=False).closest()
        if d < m:
            raise CollisionError(argument, pair, -d, m)

    def max_point_speed_bounds(self, steps: npt.ArrayLike) -> np.ndarray:
        """:meth:`max_point_speed_bound` of several joint steps ``|Δq|`` (S, nq) at once [m] (S,)."""
        self._refresh()
        return np.abs(np.asarray(steps, dtype=float)) @ self.reach

    def max_point_speed_bound(self, q_a: npt.ArrayLike, q_b: npt.ArrayLike) -> float:
        """An upper bound [m] on how far any point of the robot's bodies (and attached objects) moves between two
        configurations along the straight joint-space segment: ``Σ_j reach_j |Δq_j|``."""
        self._refresh()
        dq = np.abs(np.asarray(q_b, dtype=float) - np.asarray(q_a, dtype=float))
        return float(self.reach @ dq)


def _joined(
    batch: Any,
    names: list[tuple[str, str]],
    distance: np.ndarray,
    point_a: np.ndarray,
    point_b: np.ndarray,
    normal: np.ndarray,
    rows: np.ndarray | None,
    travel: np.ndarray,
    owner_a: np.ndarray,
    owner_b: np.ndarray,
) -> Any:
    """The engine's batch with the attached objects' pair columns after its own (Jacobian rows when ``rows``)."""
    from taplan.scene.engine import BatchDistances

    return BatchDistances(
        batch.pairs + tuple(names),
        np.hstack([batch.distance, distance]),
        np.concatenate([batch.point_a, point_a], axis=1),
        np.concatenate([batch.point_b, point_b], axis=1),
        np.concatenate([batch.normal, normal], axis=1),
        None if rows is None else np.concatenate([batch.jacobian, rows], axis=1),
        np.vstack([batch.travel, travel]),
        np.concatenate([batch.owner_a, owner_a]),
        np.concatenate([batch.owner_b, owner_b]),
    )


_ROUNDED = (shape_code(Sphere(1.0)), shape_code(Capsule(1.0, 1.0)))  # shapes that are their containing capsule
_BOX_CODE, _CYLINDER_CODE = shape_code(Box((1.0, 1.0, 1.0))), shape_code(Cylinder(1.0, 1.0))


def _containing_capsule(shape: Any) -> tuple[np.ndarray, float]:
    """A capsule containing the shape, centred in its frame: (half its core segment as a vector, its radius) [m]:
    spheres and capsules are their own; a cylinder's core is its axis with its radius; a box's its longest axis
    with the half diagonal of the other two; otherwise (meshes) the bounding sphere."""
    if isinstance(shape, (Sphere, Capsule, Cylinder)):
        return np.array([0.0, 0.0, getattr(shape, "length", 0.0) / 2]), float(shape.radius)
    if isinstance(shape, Box):
        half = np.asarray(shape.size, dtype=float) / 2
        longest = int(np.argmax(half))
        axis = np.zeros(3)
        axis[longest] = half[longest]
        return axis, float(np.linalg.norm(np.delete(half, longest)))
    return np.zeros(3), float(shape.bounding_radius())


def _support(att: _Item, direction: np.ndarray) -> np.ndarray:
    """The object's farthest points (N, 3) in its frame along unit ``direction`` (N, 3) (its frame) for the
    engine's closed-form shapes: box, sphere, capsule, cylinder (z axis)."""
    size, core = att.size, att.core
    if att.kind == _BOX_CODE:
        return np.sign(direction) * size
    point = np.zeros_like(direction)
    point[:, 2] = np.sign(direction[:, 2]) * size[2]  # capsules' and cylinders' half lengths (spheres: 0)
    if att.kind == _CYLINDER_CODE:
        across = np.hypot(direction[:, 0], direction[:, 1])
        point[:, :2] = size[0] * direction[:, :2] / np.maximum(across, 1e-12)[:, None]
        return point
    return point + core * direction


def _segment_frame(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """T_joint_capsule: the capsule's centre, z along the segment."""
    T = np.eye(4)
    T[:3, 3] = (start + end) / 2
    axis = end - start
    length = float(np.linalg.norm(axis))
    if length > 1e-9:
        z = axis / length
        helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = _cross(helper, z)
        x /= np.linalg.norm(x)
        T[:3, :3] = np.column_stack([x, _cross(z, x), z])
    return T


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of two 3-vectors, its arithmetic without its axis handling (a tenth of the time: the engine's
    penetrating pairs build a frame per coal query)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _parameter(point: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """The parameter in [0, 1] of the projection of ``point`` on the segment ``[start, end]`` (row-wise for (P, 3)
    arrays; 0 for a zero-length segment)."""
    axis = end - start
    length2 = np.sum(axis * axis, axis=-1)
    along = np.sum((point - start) * axis, axis=-1) / np.maximum(length2, 1e-18)
    return np.clip(np.where(length2 > 1e-18, along, 0.0), 0.0, 1.0)


def _closest_points(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of segment pairs [p0, p1], [q0, q1] (each (m, 3)), vectorised (zero-length segments too)."""
    s, t = segment_parameters(p0, p1, q0, q1)
    return p0 + s[:, None] * (p1 - p0), q0 + t[:, None] * (q1 - q0)
