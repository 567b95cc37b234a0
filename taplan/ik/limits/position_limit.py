"""Position limit: stay within ``[lower, upper]``, braking in time when an acceleration limit is given."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from taplan._validation import as_vector
from taplan.errors import InvalidInputError
from taplan.ik.limits.limit import StackedBoxLimit, StepContext

__all__ = ["PositionLimit"]

_SIGN = np.array([[1.0], [-1.0]])


class PositionLimit(StackedBoxLimit):
    r"""Keep ``q + v dt`` within the joint range.

    Without an acceleration limit the bound is ``gain (q_max - q) / dt`` (and the mirror image below). With an
    acceleration limit ``a`` the joint must also be able to stop before the bound after this step, decelerating at
    ``a``. With ``D = q_max - q >= 0`` this requires ``v dt + v² / (2a) <= D``, i.e.

    .. math::

        v \le \sqrt{a^2 dt^2 + 2 a D} - a\,dt .

    The bound is 0 at ``D = 0`` and, if the previous step respected it, ``v_prev - a dt`` respects the new one (the
    braking sequence stays feasible). Outside the range (``D < 0``) the bound is ``gain D / dt``: the joint is sent
    back; when the acceleration limit cannot follow, the bound is relaxed (see :mod:`taplan.ik.limits.limit`). The
    same relaxation applies when the joint already moves too fast to stop before the bound: acceleration limits win,
    so the joint brakes at ``a`` and overruns the bound by what physics requires.

    Args:
        lower: Lower bounds [rad], shape (nv,).
        upper: Upper bounds [rad], shape (nv,).
        acceleration: Braking deceleration [rad/s²], shape (nv,), or None for the plain bound.
        gain: Fraction of the remaining distance that one step may cover without braking, in (0, 1].
    """

    name = "position"
    priority = 20

    def __init__(
        self,
        lower: npt.ArrayLike,
        upper: npt.ArrayLike,
        acceleration: npt.ArrayLike | None = None,
        gain: float = 0.95,
    ) -> None:
        lo = as_vector(lower, "lower")
        hi = as_vector(upper, "upper", lo.size)
        if np.any(lo > hi):
            raise InvalidInputError("lower", lo, "lower <= upper")
        if not (np.isfinite(gain) and 0.0 < gain <= 1.0):
            raise InvalidInputError("gain", gain, "a number in (0, 1]")
        n = lo.size
        self.lower, self.upper, self.gain = lo.copy(), hi.copy(), float(gain)
        self.acceleration = None if acceleration is None else as_vector(acceleration, "acceleration", n).copy()
        if self.acceleration is not None and np.any(self.acceleration <= 0.0):
            raise InvalidInputError("acceleration", self.acceleration, "accelerations > 0 [rad/s²]")
        self._range = np.stack([self.upper, -self.lower])  # stacked: distance = range - sign q
        self._distance = np.empty((2, n))
        self._neg = np.empty((2, n))
        self._out = np.empty((2, n))
        self._two_a = None if self.acceleration is None else np.tile(2.0 * self.acceleration, (2, 1))
        self._dt = -1.0

    def stacked(self, ctx: StepContext) -> np.ndarray:
        dt = ctx.dt
        D, out = self._distance, self._out
        np.multiply(_SIGN, ctx.kin.q, out=D)
        np.subtract(self._range, D, out=D)
        if self.acceleration is None:
            np.multiply(D, self.gain / dt, out=out)  # gain max(D, 0) / dt + gain min(D, 0) / dt
            return out
        if dt != self._dt:
            self._dt = dt
            self._adt = 0.5 * self._two_a * dt
            self._adt2 = self._adt * self._adt
        inside = float(D.min()) >= 0.0
        if inside:  # within the range (the usual case)
            np.multiply(D, self._two_a, out=out)
        else:
            neg = self._neg
            np.minimum(D, 0.0, out=neg)
            neg *= self.gain / dt
            np.maximum(D, 0.0, out=out)
            out *= self._two_a
        out += self._adt2
        np.sqrt(out, out=out)
        out -= self._adt
        if not inside:
            out += self._neg
        return out
