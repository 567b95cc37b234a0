"""Compiled loops of the distance engine (numba): every (configuration, pair) of a batch in one pass.

:class:`~taplan.scene.engine.DistanceEngine` evaluated its pairs with numpy over (N configurations x pairs) arrays:
dozens of temporaries per call for a few dozen flops per pair (a batch of the optimiser's cost ~6 ms, most of it
numpy's overhead). These loops visit each pair once and call the scalar closed forms of
:mod:`taplan.scene.pair_kernels`; the engine keeps what is not a closed form (coal's penetration depths, perceived
occupancy) in Python.

The arithmetic is the numpy engine's, operation by operation. Where numpy multiplied small matrices (the obstacle
frames, the Jacobian rows) it called OpenBLAS, whose kernels add a row of three with fused multiply-adds
``fma(x2, y2, fma(x1, y1, x0 y0))``; :func:`_dot_fma` does the same, so on such a build the compiled engine returns
the numpy engine's numbers bit for bit (elsewhere they agree to rounding). ``tests/test_engine.py`` compares both on
the benchmark's scenes.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

from taplan.scene.pair_kernels import HALF_SPACE, capsule_solid, point_segment, segment_segment

__all__ = ["obstacle_pairs", "self_distances", "self_pairs", "solid_distances"]


@intrinsic
def _fma(typingctx, a, b, c):  # type: ignore[no-untyped-def]  # noqa: ANN001, ANN202, ARG001
    """``a b + c`` rounded once (LLVM's fma: the instruction where the CPU has it, else libm's exact fma)."""
    signature = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]  # noqa: ANN001, ANN202, ARG001
        return builder.fma(*args)

    return signature, codegen


@njit(cache=True, nogil=True)
def _dot_fma(x0: float, x1: float, x2: float, y0: float, y1: float, y2: float) -> float:
    """``x · y`` as OpenBLAS's matrix kernels add three terms (see the module docstring)."""
    return _fma(x2, y2, _fma(x1, y1, x0 * y0))


@njit(cache=True, nogil=True)
def _row_dot(x0: float, x1: float, x2: float, y0: float, y1: float, y2: float) -> float:
    """``x · y`` as OpenBLAS's vector-matrix kernel adds three terms for a Jacobian row ``n · J`` (the end points'
    Jacobians are stored joint-major): ``fma(x2, y2, fma(x0, y0, x1 y1))``."""
    return _fma(x2, y2, _fma(x0, y0, x1 * y1))


@njit(cache=True, nogil=True)
def _to_frame(E: np.ndarray, n: int, body: int, end: int, R: np.ndarray, c: np.ndarray, m: int) -> tuple:
    """End point ``end`` of body ``body`` at configuration ``n`` in obstacle ``m``'s frame: ``(x - c) R``."""
    v0, v1, v2 = E[n, body, end, 0] - c[m, 0], E[n, body, end, 1] - c[m, 1], E[n, body, end, 2] - c[m, 2]
    return (
        _dot_fma(v0, v1, v2, R[m, 0, 0], R[m, 1, 0], R[m, 2, 0]),
        _dot_fma(v0, v1, v2, R[m, 0, 1], R[m, 1, 1], R[m, 2, 1]),
        _dot_fma(v0, v1, v2, R[m, 0, 2], R[m, 1, 2], R[m, 2, 2]),
    )


@njit(cache=True, nogil=True)
def _to_root(x: tuple, R: np.ndarray, m: int) -> tuple:
    """A vector of obstacle ``m``'s frame in the root frame: ``x Rᵀ``."""
    return (
        _dot_fma(x[0], x[1], x[2], R[m, 0, 0], R[m, 0, 1], R[m, 0, 2]),
        _dot_fma(x[0], x[1], x[2], R[m, 1, 0], R[m, 1, 1], R[m, 1, 2]),
        _dot_fma(x[0], x[1], x[2], R[m, 2, 0], R[m, 2, 1], R[m, 2, 2]),
    )


@njit(cache=True, nogil=True)
def _end(E: np.ndarray, n: int, body: int, end: int) -> tuple:
    return E[n, body, end, 0], E[n, body, end, 1], E[n, body, end, 2]


@njit(cache=True, nogil=True)
def _unit(delta: tuple, norm: float) -> tuple:
    """``delta / norm`` where the norm is above 1e-12, else +z (the numpy engine's convention)."""
    if norm > 1e-12:
        scale = max(norm, 1e-12)
        return delta[0] / scale, delta[1] / scale, delta[2] / scale
    return 0.0, 0.0, 1.0


@njit(cache=True, nogil=True)
def _norm(x: tuple) -> float:
    """``np.linalg.norm`` of a row of three (added in order)."""
    return math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])


@njit(cache=True, nogil=True)
def _add_row(
    J: np.ndarray, n: int, column: int, JE: np.ndarray, body: int, s: float, normal: tuple, sign: float
) -> None:
    """``J[n, column] += sign n · ((1 − s) J(e0) + s J(e1))`` of body ``body``, as ``j0 + s (j1 − j0)``."""
    for v in range(J.shape[2]):
        j0 = _row_dot(normal[0], normal[1], normal[2], JE[n, body, 0, 0, v], JE[n, body, 0, 1, v], JE[n, body, 0, 2, v])
        j1 = _row_dot(normal[0], normal[1], normal[2], JE[n, body, 1, 0, v], JE[n, body, 1, 1, v], JE[n, body, 1, 2, v])
        row = j0 + s * (j1 - j0)
        if sign > 0.0:
            J[n, column, v] = row
        else:
            J[n, column, v] = J[n, column, v] - row


@njit(cache=True, nogil=True)
def _along(e0: tuple, e1: tuple, s: float) -> tuple:
    return e0[0] + s * (e1[0] - e0[0]), e0[1] + s * (e1[1] - e0[1]), e0[2] + s * (e1[2] - e0[2])


@njit(cache=True, nogil=True)
def _self_pair(E: np.ndarray, n: int, i: int, j: int) -> tuple:
    """Bodies ``i`` and ``j``'s axes at configuration ``n``: their closest points' parameters ``s``, ``t``, the
    points and their distance."""
    a0, a1, b0, b1 = _end(E, n, i, 0), _end(E, n, i, 1), _end(E, n, j, 0), _end(E, n, j, 1)
    s, t = segment_segment(a0, a1, b0, b1)
    p, q = _along(a0, a1, s), _along(b0, b1, t)
    return s, t, p, q, _norm((p[0] - q[0], p[1] - q[1], p[2] - q[2]))


@njit(cache=True, nogil=True)
def _solid_pair(
    E: np.ndarray,
    n: int,
    body: int,
    r: float,
    m: int,
    solids: tuple,
    bound_beyond: float,
) -> tuple:
    """Body ``body`` (radius ``r``) against obstacle ``m`` at configuration ``n``, in the obstacle's frame: the
    bounding spheres' gap with the segment's point nearest the centre and the centre as witnesses where that gap is
    beyond ``bound_beyond`` (not a half-space), else the closed form; as :func:`capsule_solid` returns it.
    ``solids``: the obstacles' arrays (kind (M,), rotation (M, 3, 3), centre (M, 3), bounding radius (M,), size
    (M, 3), rounding radius (M,))."""
    kind, rotation, center, bounding, size, rounding = solids
    e0 = _to_frame(E, n, body, 0, rotation, center, m)
    e1 = _to_frame(E, n, body, 1, rotation, center, m)
    s = point_segment((0.0, 0.0, 0.0), e0, e1)
    p = _along(e0, e1, s)
    centre_gap = _norm(p)
    gap = centre_gap - r - bounding[m]
    if gap > bound_beyond and kind[m] != HALF_SPACE:
        unit = _unit(p, centre_gap)
        return s, gap, (p[0] - r * unit[0], p[1] - r * unit[1], p[2] - r * unit[2]), (0.0, 0.0, 0.0), unit, False
    return capsule_solid(kind[m], (size[m, 0], size[m, 1], size[m, 2]), rounding[m], e0, e1, r)


@njit(cache=True, nogil=True)
def self_pairs(
    E: np.ndarray,
    JE: np.ndarray,
    pair_i: np.ndarray,
    pair_j: np.ndarray,
    radius: np.ndarray,
    within: float,
    jacobian: bool,
    d: np.ndarray,
    pa: np.ndarray,
    pb: np.ndarray,
    normal: np.ndarray,
    J: np.ndarray,
) -> None:
    """The robot's own pairs (body ``pair_i[k]`` against ``pair_j[k]``) at every configuration of ``E`` (N, B, 2, 3)
    into columns ``0..S-1`` of ``d`` (N, P), ``pa``, ``pb``, ``normal`` (N, P, 3) and, when ``jacobian``, the rows
    of ``J`` (N, P, nv) of the pairs at most ``within`` apart (``JE`` (N, B, 2, 3, nv); the others stay as given)."""
    for n in range(E.shape[0]):
        for k in range(pair_i.shape[0]):
            i, j = pair_i[k], pair_j[k]
            s, t, p, q, norm = _self_pair(E, n, i, j)
            unit = _unit((p[0] - q[0], p[1] - q[1], p[2] - q[2]), norm)
            ri, rj = radius[i], radius[j]
            d[n, k] = norm - ri - rj
            for x in range(3):
                pa[n, k, x] = p[x] - ri * unit[x]
                pb[n, k, x] = q[x] + rj * unit[x]
                normal[n, k, x] = unit[x]
            if jacobian and d[n, k] <= within:
                _add_row(J, n, k, JE, i, s, unit, 1.0)
                _add_row(J, n, k, JE, j, t, unit, -1.0)


@njit(cache=True, nogil=True)
def self_distances(E: np.ndarray, pair_i: np.ndarray, pair_j: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Distances (N, K) of the robot's own pairs ``pair_i[k]``, ``pair_j[k]`` at every configuration of ``E``."""
    out = np.empty((E.shape[0], pair_i.shape[0]))
    for n in range(E.shape[0]):
        for k in range(pair_i.shape[0]):
            i, j = pair_i[k], pair_j[k]
            out[n, k] = _self_pair(E, n, i, j)[4] - radius[i] - radius[j]
    return out


@njit(cache=True, nogil=True)
def obstacle_pairs(
    E: np.ndarray,
    JE: np.ndarray,
    movers: np.ndarray,
    radius: np.ndarray,
    solids: tuple,
    bound_beyond: float,
    within: float,
    jacobian: bool,
    column0: int,
    d: np.ndarray,
    pa: np.ndarray,
    pb: np.ndarray,
    normal: np.ndarray,
    J: np.ndarray,
) -> np.ndarray:
    """Moving bodies against closed-form obstacles, obstacle-major (column ``column0 + m Bm + b``), into the
    arrays of :func:`self_pairs` (``solids``: :func:`_solid_pair`'s). A pair whose bounding spheres are more than
    ``bound_beyond`` apart (not a half-space) reports that gap, witnessed by the segment's point nearest the
    obstacle's centre and the centre; the others get the closed form. Returns the (configuration, obstacle, mover)
    rows (K, 3) whose distance is a penetration depth for coal (their outputs and Jacobian rows are left to the
    caller)."""
    kind, rotation, center = solids[0], solids[1], solids[2]
    N, M, Bm = E.shape[0], kind.shape[0], movers.shape[0]
    coal_rows = np.empty((N * M * Bm, 3), dtype=np.int64)
    found = 0
    for n in range(N):
        for m in range(M):
            for b in range(Bm):
                body = movers[b]
                column = column0 + m * Bm + b
                s, gap, pa_local, pb_local, unit, inside = _solid_pair(
                    E, n, body, radius[body], m, solids, bound_beyond
                )
                if inside:
                    coal_rows[found, 0], coal_rows[found, 1], coal_rows[found, 2] = n, m, b
                    found += 1
                    continue
                d[n, column] = gap
                pa_root, pb_root = _to_root(pa_local, rotation, m), _to_root(pb_local, rotation, m)
                unit_root = _to_root(unit, rotation, m)
                for x in range(3):
                    pa[n, column, x] = pa_root[x] + center[m, x]
                    pb[n, column, x] = pb_root[x] + center[m, x]
                    normal[n, column, x] = unit_root[x]
                if jacobian and gap <= within:
                    _add_row(J, n, column, JE, body, s, unit_root, 1.0)
    return coal_rows[:found]


@njit(cache=True, nogil=True)
def solid_distances(
    E: np.ndarray,
    body: np.ndarray,
    obstacle: np.ndarray,
    radius: np.ndarray,
    solids: tuple,
    bound_beyond: float,
    out: np.ndarray,
) -> np.ndarray:
    """Distances (into ``out`` (N, K)) of the robot-obstacle pairs ``body[k]`` against ``obstacle[k]``, the numbers
    :func:`obstacle_pairs` computes for them. Returns the (configuration, pair) rows (L, 2) left to coal."""
    N, K = E.shape[0], body.shape[0]
    coal_rows = np.empty((N * K, 2), dtype=np.int64)
    found = 0
    for n in range(N):
        for k in range(K):
            b = body[k]
            gap, inside = _solid_pair(E, n, b, radius[b], obstacle[k], solids, bound_beyond)[1::4]
            if inside:
                coal_rows[found, 0], coal_rows[found, 1] = n, k
                found += 1
            out[n, k] = gap
    return coal_rows[:found]
