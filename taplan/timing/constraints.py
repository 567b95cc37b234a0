"""toppra constraint that holds joint velocity and acceleration limits inside each grid segment, not only at
gridpoints.

TOPP-RA keeps the path acceleration ``u_i`` constant on ``[s_i, s_{i+1}]``, so the squared path speed is
``x(s) = x_i + 2 u_i (s - s_i)``. At any point ``s`` of the segment the joint acceleration

.. math::

    \\ddot q(s) = q'(s)\\,u_i + q''(s)\\,x(s) = \\big(q'(s) + 2 (s - s_i)\\, q''(s)\\big)\\, u_i + q''(s)\\, x_i

and the squared path speed ``x_i + 2 (s - s_i) u_i`` are linear in the stage variables ``(u_i, x_i)``. This
constraint imposes them at the segment's start, at interior fractions (default its middle) and at its end, which is
toppra's "interpolation" scheme extended with interior points.

Every row ``a u + b x <= bound`` is divided by ``max(|a|, |b|)``: toppra's seidel LP projects onto a row's line
along ``(-b, a)`` and treats directions below 1e-10 as parallel, so rows of size 1e-5 (a velocity row
``x / x_max <= 1`` where the path barely moves, ``x_max ~ 1e5``; an acceleration row where a joint's slope was
clipped to ~1e-7 at a bound) made it return NaN, reported as "not controllable", on near-bound paths that are
perfectly feasible. The bound goes into toppra's per-stage offset ``c`` (``F`` is the identity and ``g`` ones at
every stage). Rows that cannot bind inside the LP's variable range are dropped (exactly redundant).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from toppra.constraint import DiscretizationType
from toppra.constraint.linear_constraint import LinearConstraint

__all__ = ["SegmentLimitConstraint", "PathJerkSpeedConstraint", "PathSpeedCap"]

_TINY_TANGENT = 1e-12  # [rad] per unit s: |q'| below this does not bound the path speed
_VARIABLE_RANGE = 2e8  # |u| + |x| within toppra's seidel LP (its variables stay within +-1e8)


class SegmentLimitConstraint(LinearConstraint):
    """Joint velocity and acceleration limits at several points of every TOPP-RA grid segment.

    Args:
        velocity: Maximum |joint velocity| [rad]/[s], shape (n,).
        acceleration: Maximum |joint acceleration| [rad]/[s]², shape (n,).
        fractions: Interior points of each segment where the limits are imposed as well, in (0, 1).
        scale: Per-gridpoint factor in (0, 1] applied to both limits on the segment that starts there, shape (M+1,),
            or None. Used to tighten the limits locally and re-solve.
    """

    def __init__(
        self,
        velocity: np.ndarray,
        acceleration: np.ndarray,
        fractions: Sequence[float] = (0.5,),
        scale: np.ndarray | None = None,
    ) -> None:
        super().__init__()
        self.velocity = np.asarray(velocity, dtype=float)
        self.acceleration = np.asarray(acceleration, dtype=float)
        self.fractions = np.asarray(fractions, dtype=float)
        self.scale = None if scale is None else np.asarray(scale, dtype=float)
        self.dof = self.velocity.shape[0]
        self.identical = True
        self.discretization_type = DiscretizationType.Collocation  # rows already cover the whole segment

    def compute_constraint_params(self, path, gridpoints, *args, **kwargs):  # noqa: ANN001, ANN201 (toppra API)
        n = self.dof
        grid = np.asarray(gridpoints, dtype=float)
        count = grid.shape[0]
        fractions = np.concatenate([[0.0], self.fractions, [1.0]])
        m = fractions.shape[0]
        offset = np.zeros((count, m))
        offset[:-1] = np.diff(grid)[:, None] * fractions[None, :]  # last stage: every point at s_end
        s = np.minimum(grid[:, None] + offset, grid[-1])
        d1 = np.asarray(path(s.ravel(), 1)).reshape(count, m, n)
        d2 = np.asarray(path(s.ravel(), 2)).reshape(count, m, n)
        a_acc = (d1 + 2.0 * offset[..., None] * d2).reshape(count, m * n)
        b_acc = d2.reshape(count, m * n)
        tangent = np.maximum(np.abs(d1[:, 1:-1]), _TINY_TANGENT)
        x_max = np.min((self.velocity / tangent) ** 2, axis=2)  # (count, interior)
        limit = np.broadcast_to(np.tile(self.acceleration, m), a_acc.shape)
        if self.scale is not None:  # rows <= scale * limit
            limit = limit * self.scale[:, None]
            x_max = x_max * self.scale[:, None] ** 2
        # rows a u + b x <= bound, each divided by its largest coefficient (module notes: seidel's LP needs rows of
        # unit size); toppra's c term carries the per-stage bound, since F and g are the same at every stage
        a = np.hstack([a_acc, -a_acc, 2.0 * offset[:, 1:-1]])
        b = np.hstack([b_acc, -b_acc, np.ones_like(x_max)])
        bound = np.hstack([limit, limit, x_max])
        size = np.maximum(np.abs(a), np.abs(b))
        usable = size * _VARIABLE_RANGE > bound  # else the row cannot bind for |u|, |x| <= seidel's variable range
        size = np.where(usable, size, 1.0)
        a = np.where(usable, a / size, 0.0)
        b = np.where(usable, b / size, 0.0)
        c = np.where(usable, 1.0 - bound / size, 0.0)  # row + c <= 1  <=>  (a u + b x) / size <= bound / size
        F = np.eye(a.shape[1])
        g = np.ones(a.shape[1])
        x_grid = np.min((self.velocity / np.maximum(np.abs(d1[:, 0]), _TINY_TANGENT)) ** 2, axis=1)
        if self.scale is not None:
            x_grid = x_grid * self.scale**2
        xbound = np.column_stack([np.zeros(count), x_grid])
        return a, b, c, F, g, None, xbound


class PathJerkSpeedConstraint(LinearConstraint):
    """Path-speed bound from the path's third derivative: ``|q'''_j(s)| ṡ³ <= fraction · jerk_j``.

    The joint jerk along a path is ``q' s⃛ + 3 q'' ṡ s̈ + q''' ṡ³``; the last term depends on the speed only, so it is
    bounded before any jerk-limiting of the timing. For the cubic spline ``q'''`` is constant on each waypoint
    interval, so the bound (on ``x = ṡ²``) is imposed at every gridpoint with the larger of its two sides.

    Args:
        jerk: Maximum |joint jerk| [rad]/[s]³, shape (n,).
        fraction: Share of the jerk limit the speed may use, in (0, 1].
    """

    def __init__(self, jerk: np.ndarray, fraction: float) -> None:
        super().__init__()
        self.jerk = np.asarray(jerk, dtype=float)
        self.fraction = float(fraction)
        self.dof = self.jerk.shape[0]
        self.discretization_type = DiscretizationType.Collocation

    def compute_constraint_params(self, path, gridpoints, *args, **kwargs):  # noqa: ANN001, ANN201 (toppra API)
        grid = np.asarray(gridpoints, dtype=float)
        eps = 1e-9 * max(1.0, float(grid[-1] - grid[0]))
        left = np.abs(np.asarray(path(np.maximum(grid - eps, grid[0]), 3)))
        right = np.abs(np.asarray(path(np.minimum(grid + eps, grid[-1]), 3)))
        third = np.maximum(np.maximum(left, right), _TINY_TANGENT)
        x_max = np.min((self.fraction * self.jerk / third) ** (2.0 / 3.0), axis=1)
        xbound = np.column_stack([np.zeros_like(x_max), x_max])
        return None, None, None, None, None, None, xbound


class PathSpeedCap(LinearConstraint):
    """``ṡ <= max_speed`` everywhere: with the path parameter in seconds of a recording, ``max_speed = 1`` never runs
    ahead of the recording (TOPP-RA then keeps its timing wherever the limits allow it, and slows down elsewhere).

    ``x = ṡ²`` is linear in ``s`` on each grid segment, so the bound at the gridpoints holds in between.
    """

    def __init__(self, max_speed: float) -> None:
        super().__init__()
        self.max_speed = float(max_speed)
        self.dof = 1
        self.discretization_type = DiscretizationType.Collocation

    def compute_constraint_params(self, path, gridpoints, *args, **kwargs):  # noqa: ANN001, ANN201 (toppra API)
        count = np.asarray(gridpoints).shape[0]
        xbound = np.column_stack([np.zeros(count), np.full(count, self.max_speed**2)])
        return None, None, None, None, None, None, xbound
