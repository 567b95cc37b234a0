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

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from taplan.errors import CollisionError, InvalidInputError
from taplan.scene.robot_bodies import Body, allowed_pairs, robot_bodies
from taplan.scene.scene import Scene
from taplan.scene.shapes import HalfSpace

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


class CollisionWorld:
    """The robot, its allowed pairs and a scene, evaluated at configurations.

    Args:
        robot: The robot.
        scene: Obstacles and attached objects (changes are picked up through ``scene.version``); None: self only.
        margin: Default clearance [m] for :meth:`in_collision` and :meth:`check_configuration`.
        self_collision: Include robot-robot pairs.
    """

    def __init__(self, robot: Robot, scene: Scene | None = None, *, margin: float = 0.0, self_collision: bool = True):
        import coal

        self._coal = coal
        if not (isinstance(margin, (int, float)) and math.isfinite(margin) and margin >= 0):
            raise InvalidInputError("margin", margin, "a clearance >= 0 [m]")
        self.robot = robot
        self.scene = scene if scene is not None else Scene()
        self.margin = float(margin)
        self.model = robot.model
        self.data = robot.model.createData()
        self.bodies: list[Body] = robot_bodies(robot)
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
        self._body_geometry = []
        for b in self.bodies:
            length = float(np.linalg.norm(b.end - b.start))
            geometry = coal.Capsule(b.radius, length) if length > 1e-9 else coal.Sphere(b.radius)
            self._body_geometry.append((geometry, _segment_frame(b.start, b.end)))
        self.reach = self._reach()
        self._version = -1
        self._items: list[_Item] = []
        self._request = coal.DistanceRequest()
        self._request.enable_signed_distance = True

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
        self._items = [_Item(o.name, o.shape, o.pose) for o in self.scene.obstacles.values()]
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
        q = self._configuration(q)
        self._refresh()
        model, data = self.model, self.data
        if jacobian:
            pin.computeJointJacobians(model, data, q)
        else:
            pin.forwardKinematics(model, data, q)
        pin.updateFramePlacements(model, data)
        segments = [(data.oMi[b.joint].act(b.start), data.oMi[b.joint].act(b.end)) for b in self.bodies]
        names: list[tuple[str, str]] = []
        dist: list[float] = []
        pa_list: list[np.ndarray] = []
        pb_list: list[np.ndarray] = []
        normals: list[np.ndarray] = []
        owners: list[tuple[int, int]] = []  # (joint of a, joint of b) for the Jacobian; -1: fixed
        travel: list[np.ndarray] = []  # per pair: how fast its distance can change per |Δq| [m/rad]
        if self.self_pairs:
            ends = np.array(segments)  # (B, 2, 3)
            i_idx, j_idx = self._self_index
            pa_all, pb_all = _closest_points(ends[i_idx, 0], ends[i_idx, 1], ends[j_idx, 0], ends[j_idx, 1])
            delta = pa_all - pb_all
            norm = np.linalg.norm(delta, axis=1)
            d_all = norm - self._radius[i_idx] - self._radius[j_idx]
            n_all = np.where(norm[:, None] > 1e-12, delta / np.maximum(norm, 1e-12)[:, None], [0.0, 0.0, 1.0])
            for k in np.flatnonzero(d_all <= cutoff):
                a, b = self.bodies[i_idx[k]], self.bodies[j_idx[k]]
                names.append((a.name, b.name))
                dist.append(float(d_all[k]))
                pa_list.append(pa_all[k] - a.radius * n_all[k])
                pb_list.append(pb_all[k] + b.radius * n_all[k])
                normals.append(n_all[k])
                owners.append((a.joint, b.joint))
                travel.append(self._body_reach[i_idx[k]] + self._body_reach[j_idx[k]])
        body_transforms = None
        for item in self._attached_items():
            T = data.oMf[item.frame].homogeneous @ item.pose
            item.transform = self._coal.Transform3s(T[:3, :3], T[:3, 3])
            item.center = T[:3, 3]
        for item in self._items:
            item.center = item.pose[:3, 3]
        # bodies fixed to the root never move relative to an obstacle: a plan cannot change those distances
        movers = [(k, b, segments[k]) for k, b in enumerate(self.bodies) if b.joint != 0]
        for item in self._items:
            for k, b, (s0, s1) in movers:
                if item.halfspace:  # a capsule against a plane: exact in closed form
                    gap, lowest = _halfspace_gap(item.pose, s0, s1)
                    d = gap - b.radius
                    if d > cutoff:
                        continue
                    n = item.pose[:3, 2].copy()
                    pa = lowest - b.radius * n
                    pb = lowest - gap * n
                else:
                    bound = _segment_point_distance(s0, s1, item.center) - b.radius - item.radius
                    if bound > cutoff:
                        continue
                    if bound > bound_beyond:  # far: the bounding spheres' gap is a valid lower bound
                        d, pa, pb = bound, (s0 + s1) / 2, item.center
                        n = pa - pb
                        n = n / max(float(np.linalg.norm(n)), 1e-12)
                    else:
                        if body_transforms is None:
                            body_transforms = self._body_transforms()
                        geometry, transform = self._body_geometry_at(k, body_transforms)
                        self._pair(item.geometry, item.transform, geometry, transform, item.name, b.name)
                        d, pa, pb, n = self._last
                        if d > cutoff:
                            continue
                names.append((b.name, item.name))
                dist.append(d)
                pa_list.append(pa)
                pb_list.append(pb)
                normals.append(n)
                owners.append((b.joint, 0))
                travel.append(self._body_reach[k])
        for att in self._attached_items():
            parent = self.model.frames[att.frame].parentJoint
            others = [
                (item.name, item.geometry, item.transform, item.center, item.radius, 0, item.halfspace, None)
                for item in self._items
            ]
            if body_transforms is None:
                body_transforms = self._body_transforms()
            for k, b in enumerate(self.bodies):
                if b.name in att.touch:
                    continue
                geometry, transform = self._body_geometry_at(k, body_transforms)
                center = (segments[k][0] + segments[k][1]) / 2
                radius = b.radius + float(np.linalg.norm(segments[k][1] - segments[k][0])) / 2
                others.append((b.name, geometry, transform, center, radius, b.joint, False, self._body_reach[k]))
            for name, geometry, transform, center, radius, joint, halfspace, row in others:
                if not halfspace and np.linalg.norm(center - att.center) - radius - att.radius > cutoff:
                    continue
                self._pair(geometry, transform, att.geometry, att.transform, name, att.name)
                d, pa, pb, n = self._last
                if d > cutoff:
                    continue
                names.append((att.name, name))
                dist.append(d)
                pa_list.append(pa)
                pb_list.append(pb)
                normals.append(n)
                owners.append((-(parent + 1), joint))  # negative: the attached object's parent joint
                travel.append(att.reach if row is None else att.reach + row)
        count = len(names)
        P = np.zeros((count, 3))
        point_a = np.array(pa_list).reshape(count, 3) if count else P
        point_b = np.array(pb_list).reshape(count, 3) if count else P.copy()
        normal = np.array(normals).reshape(count, 3) if count else P.copy()
        J = None
        if jacobian:
            J = np.zeros((count, model.nv))
            for k, (ja, jb) in enumerate(owners):
                ja = -ja - 1 if ja < 0 else ja
                if ja > 0:
                    J[k] += self._point_row(ja, point_a[k], normal[k])
                if jb > 0:
                    J[k] -= self._point_row(jb, point_b[k], normal[k])
        rows = np.array(travel).reshape(count, model.nv) if count else np.zeros((0, model.nv))
        return Distances(tuple(names), np.asarray(dist, dtype=float), point_a, point_b, normal, J, rows)

    def _attached_items(self) -> list[_Item]:
        return getattr(self, "_attached", [])

    def _body_transforms(self) -> list[Any]:
        """Each body's coal transform at the configuration held in ``self.data``."""
        out = []
        for b, (_, local) in zip(self.bodies, self._body_geometry, strict=True):
            T = self.data.oMi[b.joint].homogeneous @ local
            out.append(self._coal.Transform3s(T[:3, :3], T[:3, 3]))
        return out

    def _body_geometry_at(self, k: int, transforms: list[Any]) -> tuple[Any, Any]:
        return self._body_geometry[k][0], transforms[k]

    def _pair(self, g1: Any, t1: Any, g2: Any, t2: Any, n1: str, n2: str) -> None:
        """coal distance between object 1 (b) and object 2 (a): stores (d, p_a, p_b, n from b to a)."""
        result = self._coal.DistanceResult()
        d = float(self._coal.distance(g1, t1, g2, t2, self._request, result))
        pb = np.array(result.getNearestPoint1())
        pa = np.array(result.getNearestPoint2())
        n = np.array(result.normal, dtype=float)
        norm = float(np.linalg.norm(n))
        n = n / norm if norm > 1e-12 else np.array([0.0, 0.0, 1.0])
        self._last = (d, pa, pb, n)

    def _point_row(self, joint: int, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
        J = pin.getJointJacobian(self.model, self.data, joint, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        r = point - self.data.oMi[joint].translation
        return normal @ J[:3] + np.cross(r, normal) @ J[3:]

    def min_distance(self, q: npt.ArrayLike) -> tuple[float, tuple[str, str]]:
        """The smallest signed distance [m] over the active pairs, and its pair."""
        return self.distances(q, jacobian=False).closest()

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

    def max_point_speed_bound(self, q_a: npt.ArrayLike, q_b: npt.ArrayLike) -> float:
        """An upper bound [m] on how far any point of the robot's bodies (and attached objects) moves between two
        configurations along the straight joint-space segment: ``Σ_j reach_j |Δq_j|``."""
        self._refresh()
        dq = np.abs(np.asarray(q_b, dtype=float) - np.asarray(q_a, dtype=float))
        return float(self.reach @ dq)


def _segment_frame(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """T_joint_capsule: the capsule's centre, z along the segment."""
    T = np.eye(4)
    T[:3, 3] = (start + end) / 2
    axis = end - start
    length = float(np.linalg.norm(axis))
    if length > 1e-9:
        z = axis / length
        helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = np.cross(helper, z)
        x /= np.linalg.norm(x)
        T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    return T


def _closest_points(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of segment pairs [p0, p1], [q0, q1] (each (m, 3)), vectorised (zero-length segments too)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    eps = 1e-12
    safe_a, safe_e = np.maximum(a, eps), np.maximum(e, eps)
    denom = a * e - b * b
    s = np.where(denom > eps, np.clip((b * f - c * e) / np.maximum(denom, eps), 0.0, 1.0), 0.0)
    s = np.where(a <= eps, 0.0, s)
    t = np.where(e <= eps, 0.0, (b * s + f) / safe_e)
    low, high = t < 0.0, t > 1.0
    s = np.where(low & (a > eps), np.clip(-c / safe_a, 0.0, 1.0), s)
    s = np.where(high & (a > eps), np.clip((b - c) / safe_a, 0.0, 1.0), s)
    t = np.clip(t, 0.0, 1.0)
    # a point-like first segment: t from the projection of p0 on the second
    t = np.where(a <= eps, np.where(e <= eps, 0.0, np.clip(f / safe_e, 0.0, 1.0)), t)
    s = np.where((e <= eps) & (a > eps), np.clip(-c / safe_a, 0.0, 1.0), s)
    return p0 + s[:, None] * d1, q0 + t[:, None] * d2


def _segment_point_distance(s0: np.ndarray, s1: np.ndarray, p: np.ndarray) -> float:
    d = s1 - s0
    denom = float(d @ d)
    t = 0.0 if denom < 1e-18 else min(max(float((p - s0) @ d) / denom, 0.0), 1.0)
    return float(np.linalg.norm(s0 + t * d - p))


def _halfspace_gap(pose: np.ndarray, s0: np.ndarray, s1: np.ndarray) -> tuple[float, np.ndarray]:
    """Smallest height [m] of the segment above the half-space's plane, and the segment end that has it."""
    n = pose[:3, 2]
    o = pose[:3, 3]
    h0, h1 = float(n @ (s0 - o)), float(n @ (s1 - o))
    return (h0, s0) if h0 <= h1 else (h1, s1)
