"""Acceleration limit: ``|v - v_prev| <= a dt``, plus braking toward the task target so a step never overshoots."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from taplan._validation import as_vector
from taplan.errors import InvalidInputError
from taplan.ik.limits.limit import BoxLimit, StepContext

__all__ = ["AccelerationLimit", "TargetBraking"]


class AccelerationLimit(BoxLimit):
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
        self._lower = np.empty(a.size)
        self._upper = np.empty(a.size)
        self._step = np.empty(a.size)
        self._dt = -1.0

    def bounds(self, ctx: StepContext) -> tuple[np.ndarray, np.ndarray]:
        if ctx.dt != self._dt:
            self._dt = ctx.dt
            np.multiply(self.acceleration, ctx.dt, out=self._step)
        np.subtract(ctx.v_prev, self._step, out=self._lower)
        np.add(ctx.v_prev, self._step, out=self._upper)
        return self._lower, self._upper


class TargetBraking(BoxLimit):
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
        self._lower = np.empty(n)
        self._upper = np.empty(n)
        self._bound = np.empty(n)
        self._mask = np.empty(n, dtype=bool)
        self._speed = np.empty(n)
        self.objective_scale = 1.0
        self._dt = -1.0

    def bounds(self, ctx: StepContext) -> tuple[np.ndarray, np.ndarray]:
        dt = ctx.dt
        if dt != self._dt:
            self._dt = dt
            self._adt = self.acceleration * dt
            self._adt2 = self._adt * self._adt
            self._two_a_dt = 2.0 * self.acceleration * dt
        bound = self._bound
        np.abs(ctx.v_free, out=bound)  # |δ| / dt
        bound *= self._two_a_dt
        bound += self._adt2
        np.sqrt(bound, out=bound)
        bound -= self._adt
        speed = self._speed
        np.abs(ctx.v_free, out=speed)
        speed += 1e-12  # [rad/s]: joints the target does not move get ratio 1, not 0/0
        np.divide(bound + 1e-12, speed, out=speed)
        self.objective_scale = min(1.0, float(speed.min()))
        np.less(ctx.v_free, 0.0, out=self._mask)  # moving down: no upper bound from braking
        np.copyto(self._upper, bound)
        self._upper[self._mask] = np.inf
        np.negative(bound, out=self._lower)
        np.greater(ctx.v_free, 0.0, out=self._mask)
        self._lower[self._mask] = -np.inf
        return self._lower, self._upper
