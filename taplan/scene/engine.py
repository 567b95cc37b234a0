"""A distance engine for batches of configurations: the robot's capsules against themselves and against closed-form
obstacles, with witness points, normals and Jacobians, for N configurations in one call.

Per configuration the robot is a set of capsules (:mod:`taplan.scene.robot_bodies`). Their end points and the end
points' Jacobians come from one generated and compiled CasADi function of ``q`` (the approach of the IK kernel,
:mod:`taplan.ik._native`: a few microseconds per configuration), or from pinocchio when no C compiler is available.
Every distance is then computed in closed form, pair by pair in compiled loops over all configurations and pairs
(:mod:`taplan.scene.engine_kernels`, calling the scalar closed forms of :mod:`taplan.scene.pair_kernels`; the numpy
functions below are the same forms over arrays, for the world's attached objects):

* robot capsule vs robot capsule, vs obstacle capsule and vs sphere: segment–segment (a sphere is a segment of zero
  length) minus the radii;
* vs half-space: the lower end point's height minus the radius;
* vs box: the exact squared distance from the segment to the box is a convex piecewise quadratic in the segment
  parameter whose pieces end where the segment crosses a face plane (at most six crossings): each piece is minimised
  in closed form;
* vs cylinder: the capsule around the cylinder's axis shares its lateral surface, so where the nearest point on the
  axis is inside the axis segment the capsule's closed form is exact; near a cap or rim the (convex) distance from
  a point of the segment to the cylinder is searched along the segment, its parameter narrowed to 1e-10.

A capsule whose axis touches or enters a box or cylinder has a penetration depth that is not a point distance:
those pairs (only in collision) are handed to coal's EPA, as are meshes. The Jacobian of a distance with unit
normal ``n`` (from b to a) and witness parameter ``s`` on a robot segment ``[e0, e1]`` is
``n · ((1 − s) J(e0) + s J(e1))`` (minus the same for a robot member b): a point's Jacobian is affine in the point,
and the witness's offset ``r n`` from the axis adds ``n · (ω × n) = 0``.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

from taplan.scene import engine_kernels as kernels
from taplan.scene.shapes import Box, Capsule, Cylinder, HalfSpace, Sphere

if TYPE_CHECKING:
    from taplan.scene.world import CollisionWorld

__all__ = ["BatchDistances", "DistanceEngine", "end_point_kernel", "segment_box", "segment_cylinder"]

SEARCH_POINTS, SEARCH_ROUNDS = 10, 16  # the cylinder search's bracket: (2 / 9)^16 < 1e-10 of the segment
_TINY = 1e-18
_CLOSED = (Box, Sphere, Capsule, Cylinder, HalfSpace)


@dataclass(frozen=True)
class BatchDistances:
    """Every pair at N configurations (no cutoff).

    Attributes:
        pairs: ``(robot body, other body or obstacle)`` names: the robot pairs, then obstacle-major
            (every moving body against the first obstacle, then the second, ...). P pairs.
        distance: Signed distances [m] (N, P).
        point_a: Witness points on the robot body [m] (N, P, 3).
        point_b: Witness points on the other member [m] (N, P, 3).
        normal: Unit vectors from b to a (N, P, 3).
        jacobian: ``∂distance/∂q`` [m/rad] (N, P, nv), or None.
        travel: Reach coefficients per pair [m/rad] (P, nv) (:class:`~taplan.scene.world.Distances`).
        owner_a: Joint carrying the first member (P,). owner_b: the second's (0: fixed) (P,).
    """

    pairs: tuple[tuple[str, str], ...]
    distance: np.ndarray
    point_a: np.ndarray
    point_b: np.ndarray
    normal: np.ndarray
    jacobian: np.ndarray | None
    travel: np.ndarray
    owner_a: np.ndarray
    owner_b: np.ndarray


def supports(world: CollisionWorld) -> bool:
    """Whether the engine covers the world's scene (obstacles of closed-form shapes, and shapes that answer capsule
    distances themselves such as perceived occupancy; attached objects and other obstacles are evaluated by the world
    itself)."""
    return all(isinstance(o.shape, _CLOSED) or _is_field(o.shape) for o in world.scene.obstacles.values())


def _is_field(shape: Any) -> bool:
    """A shape that answers capsule distances itself (:class:`~taplan.scene.occupancy.Occupancy`)."""
    return hasattr(shape, "capsule_distances")


class DistanceEngine:
    """Batched distances of a :class:`~taplan.scene.world.CollisionWorld`'s robot bodies and closed-form obstacles.

    Built from the world's bodies and allowed pairs (any set of capsules and spheres on any joints), so a robot with
    more bodies needs nothing here. Obstacles are read again when the scene's version changes.
    """

    def __init__(self, world: CollisionWorld) -> None:
        self.world = world
        self.model = world.model
        bodies = world.bodies
        self.B = len(bodies)
        self.radius = np.array([b.radius for b in bodies], dtype=float)
        self.joint = np.array([b.joint for b in bodies], dtype=int)
        self.movers = world._movers
        self.self_i, self.self_j = world._self_index
        self.self_names = list(world._self_names)
        self._kinematics = _Kinematics(world)
        self._version = -1
        self._columns: dict[tuple[int, bool], Any] = {}
        self._index: tuple[Any, dict[tuple[str, str], int]] = (None, {})  # pair name -> column
        import coal

        # penetration depths (the only pairs left to coal) to the engine's own accuracy, not GJK's default 1e-6 m
        self._request = coal.DistanceRequest()
        self._request.enable_signed_distance = True
        self._request.gjk_tolerance = 1e-12
        self._request.epa_tolerance = 1e-12

    # ------------------------------------------------------------------------------------------------ scene
    def _refresh(self) -> None:
        scene = self.world.scene
        if scene.version == self._version:
            return
        obstacles = [o for o in scene.obstacles.values() if isinstance(o.shape, _CLOSED)]
        self.obstacles = obstacles
        self.kind = np.array([_KINDS[type(o.shape)] for o in obstacles], dtype=int)
        self.rotation = np.array([o.pose[:3, :3] for o in obstacles], dtype=float).reshape(-1, 3, 3)
        self.center = np.array([o.pose[:3, 3] for o in obstacles], dtype=float).reshape(-1, 3)
        self.bounding = np.array([o.shape.bounding_radius() for o in obstacles], dtype=float)
        self.half = np.array([_half_extents(o.shape) for o in obstacles], dtype=float).reshape(-1, 3)
        self.obstacle_radius = np.array([getattr(o.shape, "radius", 0.0) for o in obstacles], dtype=float)
        self.coal_geometry = [o.shape.to_coal() for o in obstacles]
        self.fields = [o for o in scene.obstacles.values() if _is_field(o.shape)]
        self._version = scene.version

    @property
    def pair_names(self) -> list[tuple[str, str]]:
        self._refresh()
        bodies = self.world.bodies
        names = list(self.self_names)
        names += [(bodies[b].name, o.name) for o in self.obstacles + self.fields for b in self.movers]
        return names

    # --------------------------------------------------------------------------------------------- evaluate
    def segments(self, Q: np.ndarray, jacobian: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Body segment end points (N, B, 2, 3) [m] and their Jacobians (N, B, 2, 3, nv) or None."""
        return self._kinematics(np.asarray(Q, dtype=float), jacobian)

    def evaluate(
        self,
        Q: np.ndarray,
        *,
        jacobian: bool = True,
        bound_beyond: float = math.inf,
        obstacles: bool = True,
        jacobian_within: float = math.inf,
    ) -> BatchDistances:
        """All pairs at the configurations ``Q`` (N, nq). Robot–obstacle pairs whose bounding spheres are more than
        ``bound_beyond`` [m] apart report that gap (a lower bound of their distance) without the exact query.
        Jacobian rows are computed only for the pairs at most ``jacobian_within`` [m] apart (the others' rows are
        zero): a caller that keeps the pairs within a cutoff needs no more, and the rows of all pairs were four
        fifths of a batch's cost."""
        self._refresh()
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        E, JE = self.segments(Q, jacobian)
        names, travel, owner_a, owner_b = self._pair_columns(obstacles)
        N, P = len(Q), len(names)
        d, pa, pb, n = np.empty((N, P)), np.empty((N, P, 3)), np.empty((N, P, 3)), np.empty((N, P, 3))
        J = None if JE is None else np.zeros((N, P, JE.shape[-1]))
        within = float(jacobian_within)
        kernels.self_pairs(
            E, _rows_in(JE), self.self_i, self.self_j, self.radius, within, J is not None, d, pa, pb, n, _rows_out(J)
        )
        if obstacles and self.obstacles:
            self._obstacle_pairs(E, JE, float(bound_beyond), within, (d, pa, pb, n, J))
        if obstacles and self.fields:
            start = len(self.self_i) + len(self.obstacles) * len(self.movers)
            for out, part in zip((d, pa, pb, n, J), self._field_pairs(E, JE, bound_beyond), strict=True):
                if out is not None:
                    out[:, start:] = part
        return BatchDistances(names, d, pa, pb, n, J, travel, owner_a, owner_b)

    def columns_of(self, pairs: tuple[tuple[str, str], ...]) -> np.ndarray | None:
        """The columns of the named pairs in :meth:`evaluate`'s pairs (with obstacles), or None when one is not the
        engine's (an attached object's pair)."""
        names = self.pair_columns()[0]
        if self._index[0] is not names:
            self._index = (names, {pair: k for k, pair in enumerate(names)})
        index = self._index[1]
        found = [index.get(pair, -1) for pair in pairs]
        return None if -1 in found else np.array(found, dtype=int)

    def distances_of(self, Q: np.ndarray, columns: np.ndarray, *, bound_beyond: float = math.inf) -> np.ndarray:
        """The distances (N, K) [m] of the pairs ``columns`` (K indices into :meth:`evaluate`'s pairs with
        obstacles) at the configurations ``Q`` (N, nq): the same numbers as ``evaluate(Q, jacobian=False,
        bound_beyond=bound_beyond).distance[:, columns]``, without the other pairs, the witness points or the
        normals. A certificate's later levels need a handful of pairs (those not yet certified on an interval)."""
        self._refresh()
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        columns = np.asarray(columns, dtype=int)
        E, _ = self.segments(Q, False)
        N, S, Bm = len(Q), len(self.self_i), len(self.movers)
        M = len(self.obstacles)
        out = np.empty((N, len(columns)))
        own = np.flatnonzero(columns < S)
        if own.size:
            pairs = columns[own]
            out[:, own] = kernels.self_distances(E, self.self_i[pairs], self.self_j[pairs], self.radius)
        solid = np.flatnonzero((columns >= S) & (columns < S + M * Bm))
        if solid.size:
            out[:, solid] = self._solid_distances(E, columns[solid] - S, bound_beyond)
        field = np.flatnonzero(columns >= S + M * Bm)
        for f, obstacle in enumerate(self.fields):
            mine = field[(columns[field] - S - M * Bm) // Bm == f]
            if not mine.size:
                continue
            bodies = self.movers[(columns[mine] - S - M * Bm) % Bm]
            R, c = obstacle.pose[:3, :3], obstacle.pose[:3, 3]
            e0 = ((E[:, bodies, 0] - c) @ R).reshape(-1, 3)
            e1 = ((E[:, bodies, 1] - c) @ R).reshape(-1, 3)
            radii = np.tile(self.radius[bodies], N)
            d = obstacle.shape.capsule_distances(e0, e1, radii, math.inf, bound_beyond)[0]
            out[:, mine] = d.reshape(N, -1)
        return out

    def _solid_distances(self, E: np.ndarray, flat: np.ndarray, bound_beyond: float) -> np.ndarray:
        """Distances (N, K) of robot-obstacle pairs ``flat`` (obstacle-major indices ``m * Bm + b``) as
        :meth:`_obstacle_pairs` computes them: the bounding-sphere gap beyond ``bound_beyond``, the closed forms,
        coal for a penetrating axis."""
        Bm = len(self.movers)
        m, body = flat // Bm, self.movers[flat % Bm]
        out = np.empty((len(E), len(flat)))
        penetrating = kernels.solid_distances(E, body, m, self.radius, self._solids(), float(bound_beyond), out)
        for n_, k_ in penetrating.tolist():
            out[n_, k_] = self._coal(E[n_, body[k_]], int(body[k_]), int(m[k_]))[0]
        return out

    def pair_columns(self) -> tuple[tuple[tuple[str, str], ...], np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`evaluate`'s pairs (with obstacles): names, travel rows (P, nv), owners of both members (P,)."""
        return self._pair_columns(True)

    def _pair_columns(self, obstacles: bool) -> tuple[tuple[tuple[str, str], ...], np.ndarray, np.ndarray, np.ndarray]:
        """The pairs' names, travel rows and owners, built once per scene version: the same objects every call,
        so that a caller can map its columns once (the certificates' batches)."""
        self._refresh()
        key = (self._version, obstacles)
        cached = self._columns.get(key)
        if cached is not None:
            return cached
        others = self.obstacles + self.fields if obstacles else []
        names = self.self_names + [(self.world.bodies[b].name, o.name) for o in others for b in self.movers]
        reach = self.world._body_reach
        M = len(others)
        travel = np.concatenate([reach[self.self_i] + reach[self.self_j], np.tile(reach[self.movers], (M, 1))])
        owner_a = np.concatenate([self.joint[self.self_i], np.tile(self.joint[self.movers], M)])
        owner_b = np.concatenate([self.joint[self.self_j], np.zeros(M * len(self.movers), dtype=int)])
        for array in (travel, owner_a, owner_b):
            array.flags.writeable = False  # shared by every batch of this scene version
        self._columns = {key: (tuple(names), travel, owner_a, owner_b)}
        return self._columns[key]

    def _solids(self) -> tuple[np.ndarray, ...]:
        """The closed-form obstacles as the compiled loops take them: kind, rotation, centre, bounding radius, size,
        rounding radius."""
        return self.kind, self.rotation, self.center, self.bounding, self.half, self.obstacle_radius

    def _obstacle_pairs(
        self, E: np.ndarray, JE: np.ndarray | None, bound_beyond: float, within: float, out: tuple[Any, ...]
    ) -> None:
        """Moving bodies vs closed-form obstacles into their columns of ``out`` (distance, witnesses, normal,
        Jacobian or None), obstacle-major ``S + m·Bm + b``: the compiled loop, then coal for the pairs whose axis
        touches or enters a box or cylinder (or a capsule inside a cylinder: coal's depth there, so that both paths
        agree to 1e-9 m)."""
        d, pa, pb, normal, J = out
        S, movers = len(self.self_i), self.movers
        penetrating = kernels.obstacle_pairs(
            E, _rows_in(JE), movers, self.radius, self._solids(), bound_beyond, within, J is not None, S,
            d, pa, pb, normal, _rows_out(J),
        )  # fmt: skip
        for n_, m_, b_ in penetrating.tolist():
            k = S + m_ * len(movers) + b_
            body = int(movers[b_])
            d[n_, k], pa[n_, k], pb[n_, k], normal[n_, k], s = self._coal(E[n_, body], body, m_)
            if J is not None and d[n_, k] <= within:
                J[n_, k] = _row(JE[n_, body], np.float64(s), normal[n_, k])

    def _field_pairs(self, E: np.ndarray, JE: np.ndarray | None, bound_beyond: float) -> tuple[np.ndarray, ...]:
        """Moving bodies vs obstacles that answer capsule distances themselves (occupancy voxels): one call per
        obstacle for every configuration's bodies at once, obstacle-major (N, F·Bm)."""
        movers = self.movers
        N, Bm = len(E), len(movers)
        radii = np.tile(self.radius[movers], N)
        out: list[list[np.ndarray]] = [[], [], [], [], []]
        for o in self.fields:
            R, c = o.pose[:3, :3], o.pose[:3, 3]
            e0 = ((E[:, movers, 0] - c) @ R).reshape(-1, 3)
            e1 = ((E[:, movers, 1] - c) @ R).reshape(-1, 3)
            d, pa, pb, normal = o.shape.capsule_distances(e0, e1, radii, math.inf, bound_beyond)
            # the witness's parameter on the body's axis (its point on the axis is pa + r n)
            axis = e1 - e0
            length2 = np.einsum("ij,ij->i", axis, axis)
            on_axis = pa + radii[:, None] * normal
            with np.errstate(divide="ignore", invalid="ignore"):
                s = np.where(length2 > _TINY, np.einsum("ij,ij->i", on_axis - e0, axis) / length2, 0.0)
            s = np.clip(s, 0.0, 1.0).reshape(N, Bm)
            normal_root = (normal @ R.T).reshape(N, Bm, 3)
            out[0].append(d.reshape(N, Bm))
            out[1].append((pa @ R.T + c).reshape(N, Bm, 3))
            out[2].append((pb @ R.T + c).reshape(N, Bm, 3))
            out[3].append(normal_root)
            if JE is not None:
                out[4].append(_row(JE[:, movers], s, normal_root))
        return (
            np.concatenate(out[0], axis=1),
            np.concatenate(out[1], axis=1),
            np.concatenate(out[2], axis=1),
            np.concatenate(out[3], axis=1),
            np.concatenate(out[4], axis=1) if JE is not None else None,
        )

    def _coal(self, ends: np.ndarray, body: int, item: int) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, float]:
        """coal's signed distance of body ``body`` (segment ``ends`` (2, 3), root frame) to obstacle ``item``, with
        the witness parameter on the segment."""
        import coal

        from taplan.scene.coal_query import signed_distance

        world = self.world
        start, end = ends
        frame = _segment_pose(start, end)
        geometry = world._body_geometry[body][0]
        obstacle = self.obstacles[item]
        d, pb, pa, n = signed_distance(
            coal,
            self.coal_geometry[item],
            coal.Transform3s(obstacle.pose[:3, :3], obstacle.pose[:3, 3]),
            geometry,
            coal.Transform3s(frame[:3, :3], frame[:3, 3]),
            self._request,
        )
        axis = end - start
        s = float(np.clip((pa + world.bodies[body].radius * n - start) @ axis / max(axis @ axis, _TINY), 0.0, 1.0))
        return d, pa, pb, n, s


def _segment_pose(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    from taplan.scene.world import _segment_frame

    return _segment_frame(start, end)


def _row(JE: np.ndarray, s: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """``n · ((1 − s) J(e0) + s J(e1))``: JE (..., 2, 3, nv), s (...), normal (..., 3) -> (..., nv)."""
    j0 = (normal[..., None, :] @ JE[..., 0, :, :])[..., 0, :]
    j1 = (normal[..., None, :] @ JE[..., 1, :, :])[..., 0, :]
    return j0 + s[..., None] * (j1 - j0)


def _half_extents(shape: Any) -> tuple[float, float, float]:
    if isinstance(shape, Box):
        return tuple(0.5 * np.asarray(shape.size))
    if isinstance(shape, Cylinder):
        return (shape.radius, shape.radius, 0.5 * shape.length)
    if isinstance(shape, Capsule):
        return (0.0, 0.0, 0.5 * shape.length)
    return (0.0, 0.0, 0.0)


# stand-ins for the Jacobian arrays of a batch without them (the compiled loops take arrays of fixed rank); the
# end points' rows are a strided view (the kernel's transposed output), so is this one: one compilation for both
_NO_ROWS = np.zeros((1, 1, 2, 3, 2))[..., ::2]
_NO_JACOBIAN = np.zeros((1, 1, 1))


def _rows_in(JE: np.ndarray | None) -> np.ndarray:
    return _NO_ROWS if JE is None else JE


def _rows_out(J: np.ndarray | None) -> np.ndarray:
    return _NO_JACOBIAN if J is None else J


def segment_parameters(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> tuple[np.ndarray, ...]:
    """Parameters (s, t) in [0, 1] of the closest points of segment pairs [p0, p1], [q0, q1] (each (m, 3)),
    vectorised, zero-length segments too (Ericson, Real-Time Collision Detection, 5.1.9)."""
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
    t = np.where(a <= eps, np.where(e <= eps, 0.0, np.clip(f / safe_e, 0.0, 1.0)), t)
    s = np.where((e <= eps) & (a > eps), np.clip(-c / safe_a, 0.0, 1.0), s)
    return s, t


def segment_box(e0: np.ndarray, e1: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segments (M, 3) against centred boxes of half extents (M, 3): the parameter of the segment's point nearest
    its box and the box's nearest point (M, 3). The squared distance is a convex quadratic between the parameters
    where the segment crosses a face plane; each piece is minimised exactly."""
    u = e1 - e0
    with np.errstate(divide="ignore", invalid="ignore"):
        crossings = np.concatenate([(half - e0) / u, (-half - e0) / u], axis=1)
    crossings = np.where(np.isfinite(crossings), np.clip(crossings, 0.0, 1.0), 0.0)
    M = len(e0)
    knots = np.sort(np.concatenate([np.zeros((M, 1)), crossings, np.ones((M, 1))], axis=1), axis=1)
    lo, hi = knots[:, :-1], knots[:, 1:]
    middle = e0[:, None] + ((lo + hi) / 2)[..., None] * u[:, None]
    h = half[:, None]
    side = np.where(middle > h, 1.0, np.where(middle < -h, -1.0, 0.0))  # which face plane each axis is beyond
    c = side * e0[:, None] - np.abs(side) * h  # the excess beyond it: c + t g on the piece
    g = side * u[:, None]
    A = np.einsum("mpk,mpk->mp", g, g)
    Bc = np.einsum("mpk,mpk->mp", c, g)
    t = np.clip(np.where(A > _TINY, -Bc / np.maximum(A, _TINY), lo), lo, hi)
    excess = c + t[..., None] * g
    squared = np.einsum("mpk,mpk->mp", excess, excess)
    best = np.argmin(squared, axis=1)
    s = t[np.arange(M), best]
    point = e0 + s[:, None] * u
    return s, np.clip(point, -half, half)


def _cylinder_nearest(point: np.ndarray, radius: np.ndarray, half_length: np.ndarray) -> np.ndarray:
    """The solid cylinder's point nearest each point (..., 3) (the point itself inside)."""
    rho = np.hypot(point[..., 0], point[..., 1])
    scale = np.where(rho > radius, radius / np.maximum(rho, _TINY), 1.0)
    out = point * scale[..., None]
    out[..., 2] = np.clip(point[..., 2], -half_length, half_length)
    return out


def segment_cylinder(e0: np.ndarray, e1: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segments (M, 3) against centred solid cylinders along z (``size`` (M, 3): radius, radius, half length).

    The capsule around the cylinder's axis with its radius contains the cylinder and shares its lateral surface:
    where the nearest point on the axis is strictly inside the axis segment and the segment is outside that capsule,
    the capsule's closed form is the cylinder's distance. The others (near a cap or a rim) get a bracketing
    search of the (convex) point-to-cylinder distance along the segment."""
    s, on_axis = _segment_capsule(e0, e1, size)
    t_axis = (on_axis[:, 2] + size[:, 2]) / np.maximum(2 * size[:, 2], _TINY)
    point = e0 + s[:, None] * (e1 - e0)
    lateral = (t_axis > 1e-9) & (t_axis < 1 - 1e-9) & (np.linalg.norm(point - on_axis, axis=1) > size[:, 0])
    near = _cylinder_nearest(point, size[:, 0], size[:, 2])
    rest = np.flatnonzero(~lateral)
    if rest.size:
        s[rest], near[rest] = _segment_cylinder_search(e0[rest], e1[rest], size[rest])
    return s, near


def _segment_cylinder_search(e0: np.ndarray, e1: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Search of the point-to-cylinder distance along each segment (convex: one minimum): each round evaluates
    ``SEARCH_POINTS`` evenly spaced parameters of the bracket and keeps the two intervals around the best, so the
    bracket shrinks by 2 / (SEARCH_POINTS - 1) per round (to below 1e-10 in ``SEARCH_ROUNDS``)."""
    radius, half_length = size[:, 0:1], size[:, 2:3]
    u = e1 - e0
    x0, y0, z0 = (e0[:, k : k + 1] for k in range(3))
    ux, uy, uz = (u[:, k : k + 1] for k in range(3))
    grid = np.linspace(0.0, 1.0, SEARCH_POINTS)[None]
    rows = np.arange(len(e0))
    lo, hi = np.zeros((len(e0), 1)), np.ones((len(e0), 1))
    for _ in range(SEARCH_ROUNDS):
        t = lo + (hi - lo) * grid
        radial = np.maximum(np.hypot(x0 + t * ux, y0 + t * uy) - radius, 0.0)
        axial = np.maximum(np.abs(z0 + t * uz) - half_length, 0.0)
        best = np.argmin(np.hypot(radial, axial), axis=1)
        lo = t[rows, np.maximum(best - 1, 0)][:, None]
        hi = t[rows, np.minimum(best + 1, SEARCH_POINTS - 1)][:, None]
    s = ((lo + hi) / 2)[:, 0]
    point = e0 + s[:, None] * u
    return s, _cylinder_nearest(point, size[:, 0], size[:, 2])


def _segment_capsule(e0: np.ndarray, e1: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segments against the z-axis core segments of half length ``size[:, 2]`` (capsules; spheres have 0)."""
    top = np.zeros_like(e0)
    top[:, 2] = size[:, 2]
    s, t = segment_parameters(e0, e1, -top, top)
    return s, -top + t[:, None] * 2 * top


def _segment_halfspace(e0: np.ndarray, e1: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lower end point (z) is the nearest to the plane z = 0."""
    s = np.where(e1[:, 2] < e0[:, 2], 1.0, 0.0)
    point = e0 + s[:, None] * (e1 - e0)
    return s, point * [1.0, 1.0, 0.0]


_BOX, _SPHERE, _CAPSULE, _CYLINDER, _HALF = range(5)
_KINDS = {Box: _BOX, Sphere: _SPHERE, Capsule: _CAPSULE, Cylinder: _CYLINDER, HalfSpace: _HALF}
_SOLVERS = {
    _BOX: segment_box,
    _SPHERE: _segment_capsule,
    _CAPSULE: _segment_capsule,
    _CYLINDER: segment_cylinder,
    _HALF: _segment_halfspace,
}


def solid_pairs(
    kind: np.ndarray, size: np.ndarray, core: np.ndarray, e0: np.ndarray, e1: np.ndarray, radius: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Robot capsules against solid closed-form obstacles (box, sphere, capsule, cylinder), one pair per row, each
    in its obstacle's frame: ``kind`` (P,) the obstacle's code, ``size`` (P, 3) its :func:`_half_extents`,
    ``core`` (P,) its rounding radius (sphere, capsule; ignored for the others), ``e0``, ``e1`` (P, 3) the robot
    segment, ``radius`` (P,) the robot capsule's.

    Returns (s, d, pa, pb, normal, inside): the witness parameter on the robot segment, the signed distance [m],
    the witness points on the robot capsule and on the obstacle and the unit normal from the obstacle to the robot
    (obstacle frame), and where the distance is a penetration depth that needs coal's EPA instead (the axis touches
    or enters a box or cylinder, or a capsule is inside a cylinder) -- the same cases as :meth:`DistanceEngine.
    evaluate`."""
    P = len(kind)
    s = np.zeros(P)
    near = np.zeros((P, 3))
    for code in (_BOX, _SPHERE, _CAPSULE, _CYLINDER):
        pick = np.flatnonzero(kind == code)
        if pick.size == P:  # one kind only (a table scene of boxes): no gathering
            s, near = _SOLVERS[code](e0, e1, size)
        elif pick.size:
            s[pick], near[pick] = _SOLVERS[code](e0[pick], e1[pick], size[pick])
    p = e0 + s[:, None] * (e1 - e0)
    delta = p - near
    norm = np.sqrt(np.einsum("ij,ij->i", delta, delta))
    normal = np.where(norm[:, None] > 1e-12, delta / np.maximum(norm, 1e-12)[:, None], [0.0, 0.0, 1.0])
    rounded = (kind == _SPHERE) | (kind == _CAPSULE)
    core = np.where(rounded, core, 0.0)  # a cylinder's radius is in its solver's nearest point already
    d = norm - core - radius
    pb = near + core[:, None] * normal
    pa = p - radius[:, None] * normal
    inside = ((norm <= 1e-12) & ~rounded) | ((kind == _CYLINDER) & (d < 0.0))
    return s, d, pa, pb, normal, inside


def shape_code(shape: Any) -> int:
    """The engine's code of a closed-form shape (-1: none, e.g. a mesh)."""
    return _KINDS.get(type(shape), -1)


def shape_size(shape: Any) -> tuple[float, float, float]:
    """A closed-form shape's size as the engine's solvers take it (half extents; cylinder: radius, radius, half
    length; capsule: 0, 0, half length)."""
    return _half_extents(shape)


class _Kinematics:
    """Body segment end points and their Jacobians for N configurations: a compiled CasADi function per
    configuration when a C compiler is available, else pinocchio."""

    def __init__(self, world: CollisionWorld) -> None:
        self.world = world
        self.model = world.model
        self.nv = world.model.nv
        self.B = len(world.bodies)
        self.native = _native_kernel(world)

    def __call__(self, Q: np.ndarray, jacobian: bool) -> tuple[np.ndarray, np.ndarray | None]:
        N, B, nv = len(Q), self.B, self.nv
        if self.native is not None:
            function, q_in, e_out, j_out = self.native
            E = np.empty((N, B * 6))
            JE = np.empty((N, nv, B * 6)) if jacobian else None
            with KERNEL_LOCK:  # the buffers are shared by every world of the robot, whatever thread it runs in
                for n in range(N):
                    q_in[:] = Q[n]
                    function()
                    E[n] = e_out
                    if JE is not None:
                        JE[n] = j_out.reshape(nv, B * 6)
            ends = E.reshape(N, B, 2, 3)
            rows = None if JE is None else JE.reshape(N, nv, B, 2, 3).transpose(0, 2, 3, 4, 1)
            return ends, rows
        return self._pinocchio(Q, jacobian)

    def _pinocchio(self, Q: np.ndarray, jacobian: bool) -> tuple[np.ndarray, np.ndarray | None]:
        world, model, data = self.world, self.model, self.world.data
        N, B, nv = len(Q), self.B, self.nv
        joints = world._body_joint.tolist()
        ends = np.empty((N, B, 2, 3))
        rows = np.zeros((N, B, 2, 3, nv)) if jacobian else None
        for n, q in enumerate(Q):
            if jacobian:
                pin.computeJointJacobians(model, data, q)
            else:
                pin.forwardKinematics(model, data, q)
            R = np.array([data.oMi[j].rotation for j in joints]).reshape(B, 3, 3)
            o = np.array([data.oMi[j].translation for j in joints]).reshape(B, 3)
            ends[n, :, 0] = np.einsum("bij,bj->bi", R, world._body_start) + o
            ends[n, :, 1] = np.einsum("bij,bj->bi", R, world._body_end) + o
            if rows is not None:
                J = np.asarray(data.J).reshape(6, nv)  # WORLD frame: a point's velocity is v + ω × p (nv = 1: 1-D)
                for k in range(2):
                    p = ends[n, :, k]  # (B, 3)
                    skew = np.zeros((B, 3, 3))
                    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -p[:, 2], p[:, 1], -p[:, 0]
                    skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = p[:, 2], -p[:, 1], p[:, 0]
                    # v + ω × p = J_v − [p]× J_ω
                    rows[n, :, k] = (J[None, :3] - np.einsum("bij,jv->biv", skew, J[3:])) * world._support[
                        world._body_joint
                    ][:, None, :]
        return ends, rows


_kernels: dict[tuple[Any, ...], Any] = {}
# held around every use of a kernel's buffers: the compiled call releases the GIL (ctypes), and worlds of one robot
# share a kernel across threads (a viewer's playback thread and a planner, say)
KERNEL_LOCK = threading.Lock()


def _native_kernel(world: CollisionWorld) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray] | None:
    """The compiled end point kernel of the world's bodies, checked against pinocchio, or None (numpy path).
    Cached per model and body set: worlds of one robot share it (calls are sequential and copy the outputs)."""
    key = _kernel_key(world)
    if key is None:
        return None
    if key not in _kernels:
        _kernels[key] = _checked_kernel(world)
    return _kernels[key]


def end_point_kernel(world: CollisionWorld) -> Any:
    """The compiled ``q -> body end points (6B)`` of the world's bodies without their Jacobians (a
    :class:`~taplan.ik._native.NativeFunction`, ~0.2 µs of arithmetic where the kernel with Jacobians takes ~1 µs),
    checked against pinocchio, or None (no C compiler, native code disabled). For callers that need positions only
    and call the entry point with buffers of their own (:mod:`taplan.planning.clearance_kernel`)."""
    key = _kernel_key(world)
    if key is None:
        return None
    key = (*key, "ends")
    if key not in _kernels:
        _kernels[key] = _checked_kernel(world, jacobian=False)
    found = _kernels[key]
    return None if found is None else found[0]


def _kernel_key(world: CollisionWorld) -> tuple[Any, ...] | None:
    try:
        from taplan.ik._native import native_enabled
    except ImportError:  # pragma: no cover - casadi is a dependency
        return None
    if not native_enabled():
        return None
    model = world.model
    # one key per model and body set, built from whole arrays (a new world per plan asks: ~0.1 ms instead of ~1.6)
    placements = np.array([p.homogeneous for p in model.jointPlacements])
    ends = np.round(np.array([(b.start, b.end) for b in world.bodies], dtype=float), 12) + 0.0  # + 0.0: no -0.0
    key = (
        model.name,
        model.nq,
        np.array([j.idx_q for j in model.joints]).tobytes(),
        placements.tobytes(),
        tuple(b.joint for b in world.bodies),
        ends.tobytes(),
    )
    return key


def _checked_kernel(
    world: CollisionWorld, jacobian: bool = True
) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray] | None:
    import casadi as ca

    from taplan.ik._kernel_math import joint_axes
    from taplan.ik._native import compile_function

    model = world.model
    axes = joint_axes(model)
    if axes is None:
        return None
    function = _build_kernel(world, axes, ca, jacobian)
    B, nv = len(world.bodies), model.nv
    q_in, e_out, j_out = np.zeros(model.nq), np.zeros(6 * B), np.zeros(6 * B * nv)
    native = compile_function(function, [q_in], [e_out, j_out] if jacobian else [e_out])
    if native is None:
        return None
    # the generated chain must agree with pinocchio before it is trusted
    reference = _Kinematics.__new__(_Kinematics)
    reference.world, reference.model, reference.nv, reference.B = world, model, nv, B
    rng = np.random.default_rng(0)
    Q = rng.uniform(-2.0, 2.0, (2, model.nq))
    ends, rows = reference._pinocchio(Q, True)
    for n in range(2):
        q_in[:] = Q[n]
        native()
        assert rows is not None
        got = j_out.reshape(nv, B, 2, 3).transpose(1, 2, 3, 0) if jacobian else rows[n]
        if not (np.abs(e_out.reshape(B, 2, 3) - ends[n]).max() < 1e-9 and np.abs(got - rows[n]).max() < 1e-9):
            return None
    return native, q_in, e_out, j_out


def _build_kernel(world: CollisionWorld, axes: list, ca: Any, jacobian: bool = True) -> Any:
    """The CasADi function ``q -> (end points (6B), their Jacobians (6B, nv))`` of the world's bodies (without
    ``jacobian``: ``q -> end points``)."""
    model = world.model
    q = ca.SX.sym("q", model.nq)
    rotations, origins = [ca.SX.eye(3)], [ca.SX.zeros(3)]
    world_axes: list[Any] = [None]
    for i in range(1, model.njoints):
        kind, axis = axes[i - 1]
        placement, parent = model.jointPlacements[i], model.parents[i]
        R = ca.mtimes(rotations[parent], ca.DM(placement.rotation))
        p = origins[parent] + ca.mtimes(rotations[parent], ca.DM(placement.translation))
        qi = q[model.joints[i].idx_q]
        if kind == "revolute":
            K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
            rotations.append(ca.mtimes(R, ca.DM(np.eye(3)) + ca.sin(qi) * ca.DM(K) + (1.0 - ca.cos(qi)) * ca.DM(K @ K)))
            origins.append(p)
        else:
            rotations.append(R)
            origins.append(p + qi * ca.mtimes(R, ca.DM(axis)))
        world_axes.append(ca.mtimes(R, ca.DM(axis)))
    points = []
    for b in world.bodies:
        for local in (b.start, b.end):
            points.append((b.joint, origins[b.joint] + ca.mtimes(rotations[b.joint], ca.DM(np.asarray(local)))))
    E = ca.vertcat(*[p for _, p in points])
    if not jacobian:
        return ca.Function("taplan_body_ends", [q], [E])
    J = ca.SX.zeros(3 * len(points), model.nv)
    for r, (joint, p) in enumerate(points):
        if joint == 0:
            continue
        for k in model.supports[joint]:
            if k == 0:
                continue
            col = model.joints[k].idx_v
            column = ca.cross(world_axes[k], p - origins[k]) if axes[k - 1][0] == "revolute" else world_axes[k]
            J[3 * r : 3 * r + 3, col] = column
    return ca.Function("taplan_body_points", [q], [E, J])
