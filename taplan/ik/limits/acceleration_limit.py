"""Acceleration limit: ``|v - v_prev| <= a dt``, plus braking toward the task target so a step never overshoots."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from taplan._validation import as_vector
from taplan.errors import InvalidInputError
from taplan.ik.limits.limit import StackedBoxLimit, StepContext

__all__ = ["AccelerationLimit", "TargetBraking"]

_SIGN = np.array([[1.0], [-1.0]])


class AccelerationLimit(StackedBoxLimit):
    r"""Bound the change of velocity between consecutive steps.

    The previous commanded velocity ``v_prev`` [rad/s] is explicit state (``StepContext.v_prev``, owned by the
    stepper), and the bound is

    .. math::

        v_{prev} - a\,dt \le v \le v_{prev} + a\,dt ,

    the hardest bound of the box: it is never relaxed, so every returned velocity respects it. Braking toward the
    position limits is in :class:`~taplan.ik.limits.position_limit.PositionLimit` (given the same ``a``) and braking
    toward the task target in :class:`TargetBraking`.

    Args:
        acceleration: Maximum joint acceleration [rad/s²], shape (nv,), > 0.
    """

    name = "acceleration"
    priority = 0

    def __init__(self, acceleration: npt.ArrayLike) -> None:
        a = as_vector(acceleration, "acceleration")
        if np.any(a <= 0.0):
            raise InvalidInputError("acceleration", a, "accelerations > 0 [rad/s²]")
        self.acceleration = a.copy()
        self._out = np.empty((2, a.size))
        self._dt = -1.0

    def stacked(self, ctx: StepContext) -> np.ndarray:
        if ctx.dt != self._dt:
            self._dt = ctx.dt
            self._step = np.tile(self.acceleration * ctx.dt, (2, 1))
        out = self._out
        np.multiply(_SIGN, ctx.v_prev, out=out)
        out += self._step
        return out


class TargetBraking(StackedBoxLimit):
    r"""Approach the task target no faster than the acceleration limit can stop at it.

    The objective's unconstrained minimiser ``v_free`` gives, per joint, the displacement to the (linearised)
    target ``δ = v_free dt`` [rad] (with task gain 1 this is the Gauss-Newton step). Moving toward it, the joint
    must be able to stop within ``|δ|`` after this step:

    .. math::

        v\,\mathrm{sign}(\delta) \le \sqrt{a^2 dt^2 + 2 a |\delta|} - a\,dt ,

    which is the braking bound of the position limit with the target in place of the joint limit. Without it, an
    acceleration-limited step keeps accelerating until the remaining error is below ``v dt`` and then overshoots by
    up to ``v² / (2a)``. Moving away from the target is not bounded here. Lowest priority: relaxed first.

    The joints are also coordinated: the objective's linear term is scaled by
    ``κ = min(1, min_j bound_j / |v_free_j|)`` (``objective_scale``), so its unconstrained minimiser becomes
    ``κ v_free``, the Gauss-Newton direction at the largest speed from which every joint can still stop at the
    target. Without this, joints braking independently bend the path and the frame overshoots in task space.

    A moving target is braked *relative to its motion*: with ``v_ff`` the joint velocity that follows the targets'
    velocities (``StepContext.v_ff``: explicit twists, or finite differences of successive targets), ``δ`` is
    ``(v_free - v_ff) dt`` and the bound applies to ``v - v_ff``, so the arm may move with the target at its speed
    and still only approaches the target as fast as it can stop relative to it. A target that stops is then braked
    toward exactly as a fixed one (``v_ff = 0``); only a target that stops faster than the acceleration limit allows
    can be overshot (by what braking at ``a`` from the target's speed requires). The coordination scaling also
    applies to the relative part: the minimiser becomes ``v_ff + κ (v_free - v_ff)``.

    Args:
        acceleration: Braking deceleration [rad/s²], shape (nv,).
    """

    name = "target_braking"
    priority = 30
    needs_free_velocity = True

    def __init__(self, acceleration: npt.ArrayLike) -> None:
        a = as_vector(acceleration, "acceleration")
        if np.any(a <= 0.0):
            raise InvalidInputError("acceleration", a, "accelerations > 0 [rad/s²]")
        self.acceleration = a.copy()
        n = a.size
        self._bound = np.empty(n)
        self._speed = np.empty(n)
        self._ratio = np.empty(n)
        self._relative = np.empty(n)
        self._direction = np.empty((2, n))
        self._out = np.empty((2, n))
        self.objective_scale = 1.0
        self._dt = -1.0

    def stacked(self, ctx: StepContext) -> np.ndarray:
        dt = ctx.dt
        if dt != self._dt:
            self._dt = dt
            self._adt = self.acceleration * dt
            self._adt2 = self._adt * self._adt
            self._two_a_dt = 2.0 * self.acceleration * dt
            self._two_adt = 2.0 * self._adt
        bound, speed, ratio = self._bound, self._speed, self._ratio
        moving = ctx.moving
        if moving:  # brake relative to the target's motion: δ = (v_free - v_ff) dt
            relative = self._relative
            np.subtract(ctx.v_free, ctx.v_ff, out=relative)
        else:
            relative = ctx.v_free
        np.abs(relative, out=speed)  # |δ| / dt
        # bound / speed = 2 a dt / (sqrt(a² dt² + 2 a dt speed) + a dt): no cancellation, and 1 (not 0/0) at speed 0
        np.multiply(speed, self._two_a_dt, out=ratio)
        ratio += self._adt2
        np.sqrt(ratio, out=ratio)
        ratio += self._adt
        np.divide(self._two_adt, ratio, out=ratio)
        np.multiply(ratio, speed, out=bound)
        kappa = float(ratio.min())
        # slightly below the ratio so that kappa |v_free| <= bound holds after rounding (the minimiser stays inside)
        self.objective_scale = 1.0 if kappa >= 1.0 else kappa * (1.0 - 1e-12)
        direction = self._direction
        np.multiply(_SIGN, relative, out=direction)
        out = self._out
        np.copyto(out, bound)  # broadcast to both rows
        out[direction < 0.0] = np.inf  # moving away from the target: no braking bound on that side
        if moving:
            np.multiply(_SIGN, ctx.v_ff, out=direction)
            out += direction  # upper = v_ff + bound, lower = v_ff - bound
        return out
