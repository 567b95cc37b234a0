"""Compiled scalar closed forms of one capsule pair (numba): the distance engine's formulas for one row at a time.

:mod:`taplan.scene.engine` evaluates its pairs with numpy over whole (configuration x pair) arrays; each pair's work
is a few dozen flops, so most of a batch's time was numpy's temporaries. These kernels are the same closed forms for
one pair, to be called from compiled loops (the engine's, a sampler's clearance test): points and sizes are
3-tuples of floats, results are floats and 3-tuples, nothing is allocated. They repeat the numpy functions'
arithmetic operation by operation and branch by branch (no ``fastmath``: numba does not contract a multiply-add
without it), so their results equal the numpy ones to rounding; ``tests/test_pair_kernels.py`` compares them.

Frames: a robot segment ``[e0, e1]`` is given in the obstacle's own frame (the obstacle centred at the origin, a
cylinder's or capsule's axis along z), as the engine's numpy solvers take it. Shape codes are the engine's
(:data:`BOX` ... :data:`HALF_SPACE`); ``size`` is :func:`taplan.scene.engine.shape_size`'s (half extents; cylinder:
radius, radius, half length; capsule and sphere: 0, 0, half length). Compiled once per machine (``cache=True``); the
first call of a fresh install compiles (~2-5 s for the lot).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "BOX",
    "CAPSULE",
    "CYLINDER",
    "HALF_SPACE",
    "SEARCH_POINTS",
    "SEARCH_ROUNDS",
    "SPHERE",
    "capsule_solid",
    "cylinder_nearest",
    "point_segment",
    "segment_box",
    "segment_core",
    "segment_cylinder",
    "segment_halfspace",
    "segment_segment",
]

BOX, SPHERE, CAPSULE, CYLINDER, HALF_SPACE = range(5)  # the engine's shape codes
SEARCH_POINTS, SEARCH_ROUNDS = 10, 16  # the cylinder search's bracket: (2 / 9)^16 < 1e-10 of the segment
_GRID = np.linspace(0.0, 1.0, SEARCH_POINTS)  # a global array: a compiled constant, the numpy search's own values
_TINY = 1e-18
_EPS = 1e-12  # segment_segment's degeneracy threshold (squared lengths, its determinant)


@njit(cache=True, nogil=True)
def _clip01(x: float) -> float:
    return min(max(x, 0.0), 1.0)


@njit(cache=True, nogil=True)
def _dot(a: tuple, b: tuple) -> float:
    """``a · b`` in the order numpy's ``einsum`` adds a contiguous row of three, ``(x0 + x2) + x1`` (its unrolled
    loop; ``np.linalg.norm`` and ``sum`` add in order): the rounding of the numpy code that used it."""
    return (a[0] * b[0] + a[2] * b[2]) + a[1] * b[1]


@njit(cache=True, nogil=True)
def _along(e0: tuple, e1: tuple, s: float) -> tuple:
    """``e0 + s (e1 - e0)``, the numpy code's evaluation order."""
    return (e0[0] + s * (e1[0] - e0[0]), e0[1] + s * (e1[1] - e0[1]), e0[2] + s * (e1[2] - e0[2]))


@njit(cache=True, nogil=True)
def segment_segment(p0: tuple, p1: tuple, q0: tuple, q1: tuple) -> tuple:
    """Parameters ``(s, t)`` in [0, 1] of the closest points of segments ``[p0, p1]`` and ``[q0, q1]`` (3-tuples
    [m]), zero-length segments too (Ericson, Real-Time Collision Detection, 5.1.9): the branches of
    :func:`taplan.scene.engine.segment_parameters`."""
    d1 = (p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2])
    d2 = (q1[0] - q0[0], q1[1] - q0[1], q1[2] - q0[2])
    r = (p0[0] - q0[0], p0[1] - q0[1], p0[2] - q0[2])
    a, e, f, c, b = _dot(d1, d1), _dot(d2, d2), _dot(d2, r), _dot(d1, r), _dot(d1, d2)
    safe_a, safe_e = max(a, _EPS), max(e, _EPS)
    denom = a * e - b * b
    s = _clip01((b * f - c * e) / max(denom, _EPS)) if denom > _EPS else 0.0
    if a <= _EPS:
        s = 0.0
    t = 0.0 if e <= _EPS else (b * s + f) / safe_e
    if a > _EPS:
        if t < 0.0:
            s = _clip01(-c / safe_a)
        elif t > 1.0:
            s = _clip01((b - c) / safe_a)
    t = _clip01(t)
    if a <= _EPS:
        t = 0.0 if e <= _EPS else _clip01(f / safe_e)
    elif e <= _EPS:
        s = _clip01(-c / safe_a)
    return s, t


@njit(cache=True, nogil=True)
def point_segment(point: tuple, e0: tuple, e1: tuple) -> float:
    """Parameter in [0, 1] of the point of segment ``[e0, e1]`` nearest ``point`` (0 for a zero-length segment)."""
    axis = (e1[0] - e0[0], e1[1] - e0[1], e1[2] - e0[2])
    length2 = axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]
    if length2 < _TINY:
        return 0.0
    offset = (point[0] - e0[0], point[1] - e0[1], point[2] - e0[2])
    return _clip01((offset[0] * axis[0] + offset[1] * axis[1] + offset[2] * axis[2]) / max(length2, _TINY))


@njit(cache=True, nogil=True)
def _crossing(h: float, e: float, u: float) -> float:
    """Where ``e + t u`` crosses the plane at ``h``, clipped to [0, 1]; 0 when it does not (numpy's non-finite)."""
    if u == 0.0:
        return 0.0
    t = (h - e) / u
    return _clip01(t) if math.isfinite(t) else 0.0


@njit(cache=True, nogil=True)
def _excess(e: float, u: float, h: float, middle: float) -> tuple:
    """One axis of a box piece: ``(c, g)`` with the excess beyond the face plane the piece's middle is beyond
    ``c + t g`` (0 between the planes)."""
    side = 1.0 if middle > h else (-1.0 if middle < -h else 0.0)
    return side * e - abs(side) * h, side * u


@njit(cache=True, nogil=True)
def _box_piece(lo: float, hi: float, e0: tuple, u: tuple, half: tuple) -> tuple:
    """The minimum ``(t, squared distance)`` over ``[lo, hi]`` of the squared distance from ``e0 + t u`` to the
    box: a quadratic there, minimised in closed form."""
    mid = (lo + hi) / 2
    c0, g0 = _excess(e0[0], u[0], half[0], e0[0] + mid * u[0])
    c1, g1 = _excess(e0[1], u[1], half[1], e0[1] + mid * u[1])
    c2, g2 = _excess(e0[2], u[2], half[2], e0[2] + mid * u[2])
    g = (g0, g1, g2)
    A = _dot(g, g)
    Bc = _dot((c0, c1, c2), g)
    t = -Bc / max(A, _TINY) if A > _TINY else lo
    t = min(max(t, lo), hi)
    excess = (c0 + t * g0, c1 + t * g1, c2 + t * g2)
    return t, _dot(excess, excess)


@njit(cache=True, nogil=True)
def _sorted6(a: float, b: float, c: float, d: float, e: float, f: float) -> tuple:
    """Six numbers in ascending order (an optimal 12-comparator sorting network: no array, no allocation)."""
    a, f = min(a, f), max(a, f)
    b, d = min(b, d), max(b, d)
    c, e = min(c, e), max(c, e)
    b, c = min(b, c), max(b, c)
    d, e = min(d, e), max(d, e)
    a, d = min(a, d), max(a, d)
    c, f = min(c, f), max(c, f)
    a, b = min(a, b), max(a, b)
    c, d = min(c, d), max(c, d)
    e, f = min(e, f), max(e, f)
    b, c = min(b, c), max(b, c)
    d, e = min(d, e), max(d, e)
    return a, b, c, d, e, f


@njit(cache=True, nogil=True)
def segment_box(e0: tuple, e1: tuple, half: tuple) -> tuple:
    """Segment ``[e0, e1]`` against the centred box of half extents ``half`` [m]: ``(s, near)``, the parameter of
    the segment's point nearest the box and the box's nearest point (3-tuple). The squared distance is a convex
    piecewise quadratic whose pieces end where the segment crosses a face plane; each piece is minimised exactly
    and the first smallest wins (:func:`taplan.scene.engine.segment_box`)."""
    u = (e1[0] - e0[0], e1[1] - e0[1], e1[2] - e0[2])
    k1, k2, k3, k4, k5, k6 = _sorted6(
        _crossing(half[0], e0[0], u[0]),
        _crossing(half[1], e0[1], u[1]),
        _crossing(half[2], e0[2], u[2]),
        _crossing(-half[0], e0[0], u[0]),
        _crossing(-half[1], e0[1], u[1]),
        _crossing(-half[2], e0[2], u[2]),
    )
    s, best = _box_piece(0.0, k1, e0, u, half)
    for lo, hi in ((k1, k2), (k2, k3), (k3, k4), (k4, k5), (k5, k6), (k6, 1.0)):
        t, squared = _box_piece(lo, hi, e0, u, half)
        if squared < best:
            s, best = t, squared
    p = (e0[0] + s * u[0], e0[1] + s * u[1], e0[2] + s * u[2])
    near = (
        min(max(p[0], -half[0]), half[0]),
        min(max(p[1], -half[1]), half[1]),
        min(max(p[2], -half[2]), half[2]),
    )
    return s, near


@njit(cache=True, nogil=True)
def segment_core(e0: tuple, e1: tuple, half_length: float) -> tuple:
    """Segment ``[e0, e1]`` against the z-axis core segment of half length ``half_length`` [m] (a capsule's; a
    sphere's has 0): ``(s, near)``, the parameter on the segment and the core's nearest point."""
    bottom, top = (-0.0, -0.0, -half_length), (0.0, 0.0, half_length)
    s, t = segment_segment(e0, e1, bottom, top)
    return s, (-0.0 + t * 2 * 0.0, -0.0 + t * 2 * 0.0, -half_length + t * 2 * half_length)


@njit(cache=True, nogil=True)
def cylinder_nearest(point: tuple, radius: float, half_length: float) -> tuple:
    """The point of the centred solid z-cylinder nearest ``point`` (the point itself inside)."""
    rho = math.hypot(point[0], point[1])
    scale = radius / max(rho, _TINY) if rho > radius else 1.0
    return point[0] * scale, point[1] * scale, min(max(point[2], -half_length), half_length)


@njit(cache=True, nogil=True)
def _cylinder_gap(e0: tuple, u: tuple, t: float, radius: float, half_length: float) -> float:
    radial = max(math.hypot(e0[0] + t * u[0], e0[1] + t * u[1]) - radius, 0.0)
    axial = max(abs(e0[2] + t * u[2]) - half_length, 0.0)
    return math.hypot(radial, axial)


@njit(cache=True, nogil=True)
def segment_cylinder(e0: tuple, e1: tuple, radius: float, half_length: float) -> tuple:
    """Segment ``[e0, e1]`` against the centred solid z-cylinder: ``(s, near)``.

    The capsule around the axis with the cylinder's radius shares its lateral surface: where the axis point nearest
    the segment is strictly inside the axis segment and the segment is outside that capsule, the capsule's closed
    form is exact. Otherwise (near a cap or a rim) the convex point-to-cylinder distance is searched along the
    segment: each of ``SEARCH_ROUNDS`` rounds evaluates ``SEARCH_POINTS`` evenly spaced parameters of the bracket
    and keeps the two intervals around the first best (:func:`taplan.scene.engine.segment_cylinder`)."""
    s, on_axis = segment_core(e0, e1, half_length)
    t_axis = (on_axis[2] + half_length) / max(2 * half_length, _TINY)
    p = _along(e0, e1, s)
    dx, dy, dz = p[0] - on_axis[0], p[1] - on_axis[1], p[2] - on_axis[2]
    if t_axis > 1e-9 and t_axis < 1 - 1e-9 and math.sqrt(dx * dx + dy * dy + dz * dz) > radius:
        return s, cylinder_nearest(p, radius, half_length)
    u = (e1[0] - e0[0], e1[1] - e0[1], e1[2] - e0[2])
    lo, hi = 0.0, 1.0
    for _ in range(SEARCH_ROUNDS):
        width = hi - lo
        best, best_gap = 0, _cylinder_gap(e0, u, lo + width * _GRID[0], radius, half_length)
        for k in range(1, SEARCH_POINTS):
            gap = _cylinder_gap(e0, u, lo + width * _GRID[k], radius, half_length)
            if gap < best_gap:
                best, best_gap = k, gap
        lo, hi = lo + width * _GRID[max(best - 1, 0)], lo + width * _GRID[min(best + 1, SEARCH_POINTS - 1)]
    s = (lo + hi) / 2
    p = (e0[0] + s * u[0], e0[1] + s * u[1], e0[2] + s * u[2])
    return s, cylinder_nearest(p, radius, half_length)


@njit(cache=True, nogil=True)
def segment_halfspace(e0: tuple, e1: tuple) -> tuple:
    """Segment ``[e0, e1]`` against the half-space z <= 0: ``(s, near)``, the lower end point and its foot."""
    s = 1.0 if e1[2] < e0[2] else 0.0
    p = _along(e0, e1, s)
    return s, (p[0] * 1.0, p[1] * 1.0, p[2] * 0.0)


@njit(cache=True, nogil=True)
def capsule_solid(kind: int, size: tuple, core: float, e0: tuple, e1: tuple, radius: float) -> tuple:
    """A robot capsule (axis ``[e0, e1]``, ``radius`` [m]) against a closed-form obstacle in the obstacle's frame:
    ``kind`` its shape code, ``size`` its 3-tuple size, ``core`` its rounding radius (sphere, capsule; ignored
    otherwise).

    Returns ``(s, d, pa, pb, normal, inside)``: the witness parameter on the axis, the signed distance [m], the
    witness points on the capsule and on the obstacle, the unit normal from the obstacle to the capsule (3-tuples,
    obstacle frame), and whether ``d`` is not the penetration depth (the axis touches or enters a box or
    cylinder, or the capsule is inside a cylinder: coal's EPA measures those) -- the engine's exact branch."""
    if kind == BOX:
        s, near = segment_box(e0, e1, size)
    elif kind == CYLINDER:
        s, near = segment_cylinder(e0, e1, size[0], size[2])
    elif kind == HALF_SPACE:
        s, near = segment_halfspace(e0, e1)
    else:
        s, near = segment_core(e0, e1, size[2])
    p = _along(e0, e1, s)
    delta = (p[0] - near[0], p[1] - near[1], p[2] - near[2])
    norm = math.sqrt(delta[0] * delta[0] + delta[1] * delta[1] + delta[2] * delta[2])
    if kind == HALF_SPACE:
        normal = (0.0, 0.0, 1.0)
        d = p[2] - radius
        pb = near
    else:
        if norm > 1e-12:
            scale = max(norm, 1e-12)
            normal = (delta[0] / scale, delta[1] / scale, delta[2] / scale)
        else:
            normal = (0.0, 0.0, 1.0)
        rounding = core if kind in (SPHERE, CAPSULE) else 0.0
        d = norm - rounding - radius
        pb = (near[0] + rounding * normal[0], near[1] + rounding * normal[1], near[2] + rounding * normal[2])
    pa = (p[0] - radius * normal[0], p[1] - radius * normal[1], p[2] - radius * normal[2])
    rounded = kind in (SPHERE, CAPSULE)
    inside = (norm <= 1e-12 and not rounded and kind != HALF_SPACE) or (kind == CYLINDER and d < 0.0)
    return s, d, pa, pb, normal, inside
