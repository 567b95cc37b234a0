"""Position limit: stay within ``[lower, upper]``, braking in time when an acceleration limit is given."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from taplan._validation import as_vector
from taplan.errors import InvalidInputError
from taplan.ik.limits.limit import BoxLimit, StepContext

__all__ = ["PositionLimit"]


class PositionLimit(BoxLimit):
    r"""Keep ``q + v dt`` within the joint range.

    Without an acceleration limit the bound is ``gain (q_max - q) / dt`` (and the mirror image below). With an
    acceleration limit ``a`` the joint must also be able to stop before the bound after this step, decelerating at
    ``a``. With ``D = q_max - q >= 0`` this requires ``v dt + v² / (2a) <= D``, i.e.

    .. math::

        v \le \sqrt{a^2 dt^2 + 2 a D} - a\,dt .

    The bound is 0 at ``D = 0`` and, if the previous step respected it, ``v_prev - a dt`` respects the new one (the
    braking sequence stays feasible). Outside the range (``D < 0``) the bound is ``gain D / dt``: the joint is sent
    back; when the acceleration limit cannot follow, the bound is relaxed (see :mod:`taplan.ik.limits.limit`).

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
        self._n = n
        self._distance = np.empty(2 * n)
        self._neg = np.empty(2 * n)
        self._bound = np.empty(2 * n)
        self._a2 = np.empty(2 * n) if self.acceleration is None else np.tile(self.acceleration, 2)
        self._lower_out = np.empty(n)
        self._dt = -1.0

    def bounds(self, ctx: StepContext) -> tuple[np.ndarray, np.ndarray]:
        n, dt, q = self._n, ctx.dt, ctx.kin.q
        D, neg, out = self._distance, self._neg, self._bound
        np.subtract(self.upper, q, out=D[:n])
        np.subtract(q, self.lower, out=D[n:])
        np.minimum(D, 0.0, out=neg)
        neg *= self.gain / dt
        if self.acceleration is None:
            np.maximum(D, 0.0, out=out)
            out *= self.gain / dt
        else:
            if dt != self._dt:
                self._dt = dt
                self._adt = self._a2 * dt
                self._adt2 = self._adt * self._adt
                self._two_a = 2.0 * self._a2
            np.maximum(D, 0.0, out=out)
            out *= self._two_a
            out += self._adt2
            np.sqrt(out, out=out)
            out -= self._adt
        out += neg
        np.negative(out[n:], out=self._lower_out)
        return self._lower_out, out[:n]
