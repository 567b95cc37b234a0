"""The distance engine's numpy implementation of its pairs (main 64e2df6), kept as the reference the compiled loops
(:mod:`taplan.scene.engine_kernels`) must equal: ``NumpyEngine`` is a :class:`~taplan.scene.engine.DistanceEngine`
whose ``evaluate`` and ``distances_of`` are that code, over the same kinematics, coal calls and occupancy fields."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from taplan.scene.engine import (
    _CAPSULE,
    _CYLINDER,
    _HALF,
    _SOLVERS,
    _SPHERE,
    _TINY,
    BatchDistances,
    DistanceEngine,
    _row,
    segment_parameters,
    solid_pairs,
)


class NumpyEngine(DistanceEngine):
    """The engine with its former numpy pairs (the reference of ``tests/test_engine.py``)."""

    def evaluate(
        self,
        Q: np.ndarray,
        *,
        jacobian: bool = True,
        bound_beyond: float = math.inf,
        obstacles: bool = True,
        jacobian_within: float = math.inf,
    ) -> BatchDistances:
        """The former numpy evaluation: each part's arrays, then concatenated."""
        self._refresh()
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        E, JE = self.segments(Q, jacobian)
        N = len(Q)
        parts = [self._self_pairs(E, JE, jacobian_within)]
        if obstacles and self.obstacles:
            parts.append(self._obstacle_pairs(E, JE, bound_beyond, jacobian_within))
        if obstacles and self.fields:
            parts.append(self._field_pairs(E, JE, bound_beyond))
        d = np.concatenate([p[0] for p in parts], axis=1)
        pa = np.concatenate([p[1] for p in parts], axis=1)
        pb = np.concatenate([p[2] for p in parts], axis=1)
        n = np.concatenate([p[3] for p in parts], axis=1)
        J = None
        if jacobian:  # one array, each part's rows written into its columns (the parts' zeros and a concatenation
            # of them were a third of a batch's cost)
            assert JE is not None
            J = np.zeros((N, d.shape[1], JE.shape[-1]))
            offset = 0
            for part in parts:
                rows = part[4]
                if isinstance(rows, tuple):  # (configuration, column, row) of the pairs that have one
                    J[rows[0], offset + rows[1]] = rows[2]
                else:
                    J[:, offset : offset + part[0].shape[1]] = rows
                offset += part[0].shape[1]
        names, travel, owner_a, owner_b = self._pair_columns(obstacles)
        assert d.shape == (N, len(names))
        return BatchDistances(names, d, pa, pb, n, J, travel, owner_a, owner_b)

    def distances_of(self, Q: np.ndarray, columns: np.ndarray, *, bound_beyond: float = math.inf) -> np.ndarray:
        """The robot's own pairs as the numpy code computed them; the obstacles' through :meth:`_solid_distances`
        (the numpy one below), perceived fields' as the engine computes them."""
        out = super().distances_of(Q, columns, bound_beyond=bound_beyond)
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        columns = np.asarray(columns, dtype=int)
        E, _ = self.segments(Q, False)
        N, S = len(Q), len(self.self_i)
        own = np.flatnonzero(columns < S)
        if own.size:
            i, j = self.self_i[columns[own]], self.self_j[columns[own]]
            a0, a1 = E[:, i, 0].reshape(-1, 3), E[:, i, 1].reshape(-1, 3)
            b0, b1 = E[:, j, 0].reshape(-1, 3), E[:, j, 1].reshape(-1, 3)
            u, v = segment_parameters(a0, a1, b0, b1)
            gap = np.linalg.norm(a0 + u[:, None] * (a1 - a0) - (b0 + v[:, None] * (b1 - b0)), axis=1)
            out[:, own] = gap.reshape(N, -1) - self.radius[i] - self.radius[j]
        return out

    def _solid_distances(self, E: np.ndarray, flat: np.ndarray, bound_beyond: float) -> np.ndarray:
        """Distances (N, K) of robot-obstacle pairs ``flat`` (obstacle-major indices ``m * Bm + b``) as
        :meth:`_obstacle_pairs` computes them: the bounding-sphere gap beyond ``bound_beyond``, the closed forms,
        coal for a penetrating axis."""
        Bm = len(self.movers)
        m, body = flat // Bm, self.movers[flat % Bm]
        N, K = len(E), len(flat)
        R, c = self.rotation[m], self.center[m]  # (K, 3, 3), (K, 3)
        e0 = ((E[:, body, 0] - c)[:, :, None, :] @ R[None])[:, :, 0].reshape(-1, 3)  # obstacle frames, (N K, 3)
        e1 = ((E[:, body, 1] - c)[:, :, None, :] @ R[None])[:, :, 0].reshape(-1, 3)
        kind, radius = np.tile(self.kind[m], N), np.tile(self.radius[body], N)
        core = _point_segment(np.zeros(3), e0, e1)
        centre_gap = np.linalg.norm(e0 + core[:, None] * (e1 - e0), axis=1)
        d = centre_gap - radius - np.tile(self.bounding[m], N)
        half = kind == _HALF
        exact = np.flatnonzero((d <= bound_beyond) & ~half)
        if exact.size:
            size, rounding = np.tile(self.half[m], (N, 1)), np.tile(self.obstacle_radius[m], N)
            _, d_k, *_, inside = solid_pairs(
                kind[exact], size[exact], rounding[exact], e0[exact], e1[exact], radius[exact]
            )
            d[exact] = d_k
            for row in exact[inside]:
                n_, k_ = divmod(int(row), K)
                d[row] = self._coal(E[n_, body[k_]], int(body[k_]), int(m[k_]))[0]
        lower = np.minimum(e0[half, 2], e1[half, 2])  # a half-space: the lower end point's height
        d[half] = lower - radius[half]
        return d.reshape(N, K)

    def _self_pairs(self, E: np.ndarray, JE: np.ndarray | None, within: float = math.inf) -> tuple[Any, ...]:
        i, j = self.self_i, self.self_j
        N, S = len(E), len(i)
        a0, a1 = E[:, i, 0].reshape(-1, 3), E[:, i, 1].reshape(-1, 3)
        b0, b1 = E[:, j, 0].reshape(-1, 3), E[:, j, 1].reshape(-1, 3)
        s, t = segment_parameters(a0, a1, b0, b1)
        pa, pb = a0 + s[:, None] * (a1 - a0), b0 + t[:, None] * (b1 - b0)
        delta = pa - pb
        norm = np.linalg.norm(delta, axis=1)
        normal = np.where(norm[:, None] > 1e-12, delta / np.maximum(norm, 1e-12)[:, None], [0.0, 0.0, 1.0])
        ri, rj = np.tile(self.radius[i], N), np.tile(self.radius[j], N)
        d = norm - ri - rj
        pa, pb = pa - ri[:, None] * normal, pb + rj[:, None] * normal
        rows = None
        if JE is not None:  # (configuration, column, row) of the pairs within ``within``; the others' rows are 0
            n_, k_ = np.nonzero(d.reshape(N, S) <= within)
            flat = n_ * S + k_
            nn = normal[flat]
            rows = (n_, k_, _row(JE[n_, i[k_]], s[flat], nn) - _row(JE[n_, j[k_]], t[flat], nn))
        shape = (N, S)
        return d.reshape(shape), pa.reshape(*shape, 3), pb.reshape(*shape, 3), normal.reshape(*shape, 3), rows

    def _obstacle_pairs(
        self, E: np.ndarray, JE: np.ndarray | None, bound_beyond: float, within: float = math.inf
    ) -> tuple[Any, ...]:
        """Moving bodies vs obstacles, obstacle-major (N, M, Bm) flattened to (N, M·Bm). The exact distances are
        computed only for the pairs the broad phase keeps (in a cluttered scene with a cutoff, a tenth of them)."""
        movers = self.movers
        N, M, Bm = len(E), len(self.obstacles), len(movers)
        # every pair in the obstacle's frame: (N, M, Bm, 3)
        R, c = self.rotation, self.center
        # x_local = Rᵀ (x − c), as rows: (x − c) R (batched matmul: einsum with broadcasting was half the cost)
        e0 = (E[:, None, movers, 0] - c[None, :, None, :]) @ R[None]
        e1 = (E[:, None, movers, 1] - c[None, :, None, :]) @ R[None]
        shape = (N, M, Bm)
        radius = np.broadcast_to(self.radius[movers], shape)
        kind = np.broadcast_to(self.kind[None, :, None], shape)
        # broad phase: the segment's distance to the obstacle's centre minus both bounding radii
        s = _point_segment(np.zeros(3), e0, e1)  # witness parameter on the robot segment: nearest the centre
        p = e0 + s[..., None] * (e1 - e0)  # segment witness, obstacle frame
        centre_gap = np.linalg.norm(p, axis=-1)
        d = centre_gap - radius - self.bounding[None, :, None]
        far = (d > bound_beyond) & (kind != _HALF)
        # a far pair reports that gap, witnessed by the segment's point nearest the centre and the centre
        normal = np.where(centre_gap[..., None] > 1e-12, p / np.maximum(centre_gap, 1e-12)[..., None], [0.0, 0.0, 1.0])
        pa_local = p - radius[..., None] * normal
        near = np.zeros((*shape, 3))  # witness on the obstacle (its frame)
        # the exact pairs, as flat arrays of those only
        exact = np.nonzero(~far)
        inside = np.zeros(0, dtype=int)
        if exact[0].size:
            x0, x1, kx, rx, mx = e0[exact], e1[exact], kind[exact], radius[exact], exact[1]
            sx, nx_near = np.zeros(len(kx)), np.zeros((len(kx), 3))  # the core's nearest point
            for code, solver in _SOLVERS.items():
                pick = kx == code
                if pick.any():
                    sx[pick], nx_near[pick] = solver(x0[pick], x1[pick], self.half[mx[pick]])
            px = x0 + sx[:, None] * (x1 - x0)
            delta = px - nx_near
            norm = np.linalg.norm(delta, axis=-1)
            nx = np.where(norm[:, None] > 1e-12, delta / np.maximum(norm, 1e-12)[:, None], [0.0, 0.0, 1.0])
            core_radius = self.obstacle_radius[mx]
            rounded = (kx == _SPHERE) | (kx == _CAPSULE)
            half = kx == _HALF
            dx = np.where(half, px[:, 2] - rx, np.where(rounded, norm - core_radius, norm) - rx)
            nx = np.where(half[:, None], [0.0, 0.0, 1.0], nx)
            nx_near = np.where(rounded[:, None], nx_near + core_radius[:, None] * nx, nx_near)
            nx_near = np.where(half[:, None], px * [1.0, 1.0, 0.0], nx_near)
            d[exact], s[exact], normal[exact] = dx, sx, nx
            pa_local[exact], near[exact] = px - rx[:, None] * nx, nx_near
            # the axis touches or enters a box or cylinder: penetration depth from coal (its EPA), not a point
            # distance (and a capsule inside a cylinder: coal's depth there, so that both paths agree to 1e-9 m)
            inside = np.flatnonzero(((norm <= 1e-12) & ~rounded & ~half) | ((kx == _CYLINDER) & (dx < 0.0)))
        # back to the root frame
        Rt = R.transpose(0, 2, 1)[None]  # rows back to the root frame: x = x_local Rᵀ + c
        pa = pa_local @ Rt + c[None, :, None]
        pb = near @ Rt + c[None, :, None]  # a far pair's: the centre
        normal = normal @ Rt
        for k in inside.tolist():
            n_, m_, b_ = exact[0][k], exact[1][k], exact[2][k]
            d[n_, m_, b_], pa[n_, m_, b_], pb[n_, m_, b_], normal[n_, m_, b_], s[n_, m_, b_] = self._coal(
                E[n_, movers[b_]], movers[b_], m_
            )
        rows = None
        if JE is not None:  # (configuration, column, row) of the pairs within ``within``; the others' rows are 0
            n_, m_, b_ = np.nonzero(d <= within)
            rows = (n_, m_ * Bm + b_, _row(JE[n_, movers[b_]], s[n_, m_, b_], normal[n_, m_, b_]))
        flat = (N, M * Bm)
        return d.reshape(flat), pa.reshape(*flat, 3), pb.reshape(*flat, 3), normal.reshape(*flat, 3), rows


def _point_segment(point: np.ndarray, e0: np.ndarray, e1: np.ndarray) -> np.ndarray:
    """Parameter in [0, 1] of the point of each segment nearest ``point``."""
    axis = e1 - e0
    length2 = (axis * axis).sum(axis=-1)
    t = ((point - e0) * axis).sum(axis=-1) / np.maximum(length2, _TINY)
    return np.clip(np.where(length2 < _TINY, 0.0, t), 0.0, 1.0)
