"""The sampler's compiled yes/no clearance test (numba): does any pair of robot capsules, or of a robot capsule and a
closed-form obstacle, come closer than ``clearance`` at one of a batch of states?

VAMP's idea on a CPU: a capsule robot against boxes, spheres, capsules, cylinders and half-spaces needs no general
collision library. Per state, each active pair first compares bounding spheres (a body's: its segment's middle,
half its length plus its radius; an obstacle's: its :meth:`~taplan.scene.shapes.Shape.bounding_radius` about its
centre), then the body's sphere against the obstacle's own shape (a table or a panel is a poor sphere); only a pair
that both leave within ``clearance`` gets its exact closed-form distance (:mod:`taplan.scene.pair_kernels`, the
distance engine's closed forms as scalar kernels). The states are tested in the order given and the first too close
one ends the test: a blocked motion usually fails at its first state or two. Along a motion, the bodies' end points
of each state come from the compiled kinematics (:func:`taplan.scene.engine.end_point_kernel`) called from the loop
itself, only for the states it gets to.

A capsule whose axis touches or enters a box or a cylinder has a negative distance whatever its depth: the engine
hands its depth to coal's EPA, a yes/no test needs only its sign (``clearance >= 0``).

Compiled once per machine (``cache=True``, beside this file: ~4 s on a fresh install, then ~0.2 s to load in a new
process). numba's cache is keyed on this file alone: after editing :mod:`taplan.scene.pair_kernels`, whose kernels
are compiled into these, touch this file (or delete its cached ``*.nbi``/``*.nbc``) in a working tree.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from taplan.scene.pair_kernels import BOX, CYLINDER, HALF_SPACE, capsule_solid, segment_segment

__all__ = ["first_blocked_along", "first_too_close"]


@njit(cache=True, nogil=True)
def _middle_gap(code, x, y, z, size, core):
    """A lower bound of the distance from the point (x, y, z) (obstacle frame) to the obstacle: exact for a box,
    cylinder, sphere or capsule."""
    if code == BOX:
        dx = max(abs(x) - size[0], 0.0)
        dy = max(abs(y) - size[1], 0.0)
        dz = max(abs(z) - size[2], 0.0)
        return math.sqrt(dx * dx + dy * dy + dz * dz)
    if code == CYLINDER:
        radial = max(math.sqrt(x * x + y * y) - size[0], 0.0)
        axial = max(abs(z) - size[2], 0.0)
        return math.sqrt(radial * radial + axial * axial)
    h = size[2]
    w = min(max(z, -h), h)
    return math.sqrt(x * x + y * y + (z - w) ** 2) - core


@njit(cache=True, nogil=True)
def _blocked(e, pairs, clearance, middle, reach):
    """Whether a pair of one state (``e`` (B, 2, 3): the bodies' end points) is closer than ``clearance``;
    ``middle`` (B, 3) and ``reach`` (B,) are scratch space for the bodies' bounding spheres."""
    radius, self_a, self_b, body, obstacle, kind, rotation, center, size, core, bounding = pairs
    B = e.shape[0]
    for b in range(B):
        x = 0.0
        for k in range(3):
            middle[b, k] = 0.5 * (e[b, 0, k] + e[b, 1, k])
            x += (e[b, 1, k] - e[b, 0, k]) ** 2
        reach[b] = 0.5 * math.sqrt(x) + radius[b]
    for k in range(self_a.shape[0]):
        i, j = self_a[k], self_b[k]
        gx, gy, gz = middle[i, 0] - middle[j, 0], middle[i, 1] - middle[j, 1], middle[i, 2] - middle[j, 2]
        if math.sqrt(gx * gx + gy * gy + gz * gz) - reach[i] - reach[j] >= clearance:
            continue
        a0, a1 = (e[i, 0, 0], e[i, 0, 1], e[i, 0, 2]), (e[i, 1, 0], e[i, 1, 1], e[i, 1, 2])
        b0, b1 = (e[j, 0, 0], e[j, 0, 1], e[j, 0, 2]), (e[j, 1, 0], e[j, 1, 1], e[j, 1, 2])
        s, t = segment_segment(a0, a1, b0, b1)
        dx = a0[0] + s * (a1[0] - a0[0]) - (b0[0] + t * (b1[0] - b0[0]))
        dy = a0[1] + s * (a1[1] - a0[1]) - (b0[1] + t * (b1[1] - b0[1]))
        dz = a0[2] + s * (a1[2] - a0[2]) - (b0[2] + t * (b1[2] - b0[2]))
        gap = math.sqrt(dx * dx + dy * dy + dz * dz)
        if gap - radius[i] - radius[j] < clearance:
            return True
    for k in range(body.shape[0]):
        b, m = body[k], obstacle[k]
        code = kind[m]
        c = center[m]
        if code != HALF_SPACE:
            gx, gy, gz = middle[b, 0] - c[0], middle[b, 1] - c[1], middle[b, 2] - c[2]
            if math.sqrt(gx * gx + gy * gy + gz * gz) - reach[b] - bounding[m] >= clearance:
                continue
        # the segment in the obstacle's frame: R^T (x - c)
        R = rotation[m]
        x0 = y0 = z0 = x1 = y1 = z1 = 0.0
        for r in range(3):
            d0, d1 = e[b, 0, r] - c[r], e[b, 1, r] - c[r]
            x0 += R[r, 0] * d0
            y0 += R[r, 1] * d0
            z0 += R[r, 2] * d0
            x1 += R[r, 0] * d1
            y1 += R[r, 1] * d1
            z1 += R[r, 2] * d1
        if (
            code != HALF_SPACE
            and _middle_gap(code, 0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * (z0 + z1), size[m], core[m]) - reach[b]
            >= clearance
        ):
            continue  # the body's bounding sphere against the shape itself: far tighter for a large panel
        size_m = (size[m, 0], size[m, 1], size[m, 2])
        _, gap, _, _, _, inside = capsule_solid(code, size_m, core[m], (x0, y0, z0), (x1, y1, z1), radius[b])
        if inside or gap < clearance:  # a penetration: its depth is coal's, a yes/no needs only its sign
            return True
    return False


@njit(cache=True, nogil=True)
def first_too_close(ends: np.ndarray, pairs: tuple, clearance: float) -> int:
    """The index of the first state with a pair closer than ``clearance`` [m] (>= 0), or -1 when every pair of every
    state keeps it.

    ``ends`` (N, B, 2, 3): the bodies' segment end points per state (root frame). ``pairs``: ``(radius, self_a,
    self_b, body, obstacle, kind, rotation, center, size, core, bounding)``: the bodies' radii (B,); the robot pairs'
    bodies ``self_a[k]``, ``self_b[k]``; the robot-obstacle pairs' body ``body[k]`` and obstacle ``obstacle[k]``;
    per obstacle its shape code (:func:`taplan.scene.engine.shape_code`), ``rotation`` (3, 3) and ``center`` (3,)
    (its pose in the root frame), ``size`` (:func:`taplan.scene.engine.shape_size`), ``core`` (the rounding radius
    of a sphere or capsule) and ``bounding`` radius (0 for a half-space)."""
    N, B = ends.shape[0], ends.shape[1]
    middle, reach = np.empty((B, 3)), np.empty(B)
    for n in range(N):
        if _blocked(ends[n], pairs, clearance, middle, reach):
            return n
    return -1


@njit(cache=True, nogil=True)
def first_blocked_along(
    native: tuple, q_a: np.ndarray, q_b: np.ndarray, fractions: np.ndarray, pairs: tuple, clearance: float
) -> int:
    """:func:`first_too_close` at the states ``q_a + f (q_b - q_a)`` for ``f`` in ``fractions`` in that order, their
    bodies' end points from the compiled kinematics ``native`` (address of the C entry point, its arg, res, iw and w
    arrays, and the input ``q`` and output ``e`` buffers those point to): a state's kinematics only when the states
    before it were clear."""
    address, arg, res, iw, w, q, e = native
    ends = e.reshape(-1, 2, 3)
    B = ends.shape[0]
    middle, reach = np.empty((B, 3)), np.empty(B)
    for n in range(fractions.shape[0]):
        f = fractions[n]
        for i in range(q.shape[0]):
            q[i] = q_a[i] + f * (q_b[i] - q_a[i])  # as numpy's q_a + f * (q_b - q_a)
        if _call_native(address, arg.ctypes.data, res.ctypes.data, iw.ctypes.data, w.ctypes.data) != 0:
            return -2  # the kernel failed (it does not)
        if _blocked(ends, pairs, clearance, middle, reach):
            return n
    return -1


@intrinsic
def _call_native(typingctx, address, arg, res, iw, w):  # noqa: ARG001 - numba's signature
    """Calls the C function ``int f(const double** arg, double** res, long long* iw, double* w, int mem)`` at
    ``address`` (a CasADi-generated kernel, :class:`~taplan.ik._native.NativeFunction`) with ``mem = 0``; the
    pointers are passed as integers (the arrays' ``ctypes.data``)."""
    signature = types.int32(address, arg, res, iw, w)

    def codegen(context, builder, signature, args):  # noqa: ARG001
        pointer = ir.IntType(8).as_pointer()
        kind = ir.FunctionType(ir.IntType(32), [pointer, pointer, pointer, pointer, ir.IntType(32)])
        function = builder.inttoptr(args[0], kind.as_pointer())
        pointers = [builder.inttoptr(a, pointer) for a in args[1:]]
        return builder.call(function, [*pointers, ir.Constant(ir.IntType(32), 0)])

    return signature, codegen
