"""Limit base classes and the relaxed intersection that keeps the velocity box non-empty.

Box limits bound each joint velocity ``v`` [rad/s] independently and become the QP's variable bounds. They are
intersected in priority order (lowest first); when a later (softer) bound does not meet the interval built so far,
it is relaxed to the nearest point of that interval instead of making the problem infeasible. The order used by
:class:`taplan.ik.DifferentialIK` is:

1. acceleration ``|v - v_prev| <= a dt`` (never relaxed),
2. velocity ``|v| <= v_max`` (relaxed only if the previous velocity itself exceeds it: the joint then decelerates at
   the acceleration limit),
3. position (with braking distance; relaxed when the state is outside the limits or too fast to stop in time: the
   joint then brakes or returns at the acceleration limit),
4. braking toward the task target (relaxed like 3).

So the acceleration limit always wins: a joint that moves too fast to stop before its position limit (e.g. a state
handed to ``reset`` with a large velocity next to a bound) brakes at the full acceleration limit and crosses the bound
by what physics requires, ``v² / (2a)`` minus the remaining distance, then comes back.

Row limits (collision avoidance) are inequality rows ``G v <= h`` made soft by one slack variable each with a large
penalty, so they can never make the QP infeasible either.

Internally a box is *stacked*: an array (2, nv) whose rows are ``upper`` and ``-lower``, so one elementwise minimum
intersects both sides and the relaxation is a maximum with the row-swapped, negated previous box.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass

import numpy as np

from taplan.ik._kinematics import Kinematics

__all__ = ["BoxLimit", "RowLimit", "StepContext", "intersect_relaxed", "intersect_stacked"]


@dataclass
class StepContext:
    """What limits see of the current step.

    Attributes:
        kin: Kinematics at the current configuration ``kin.q`` [rad].
        dt: Step duration [s].
        v_prev: Previous commanded velocity [rad/s], shape (nv,).
        v_free: Minimiser of the objective without constraints [rad/s], shape (nv,) (filled by the problem
            builder before the box limits are evaluated).
        v_ff: Joint velocity that follows the task targets' motion [rad/s], shape (nv,): the objective's
            minimiser for the targets' velocities alone (valid when ``moving``).
        moving: Whether some task target moves this step (else ``v_ff`` is stale and should be read as zero).
    """

    kin: Kinematics
    dt: float
    v_prev: np.ndarray
    v_free: np.ndarray
    v_ff: np.ndarray | None = None
    moving: bool = False


class BoxLimit(abc.ABC):
    """A limit that bounds each joint velocity: ``lower <= v <= upper`` [rad/s].

    Subclasses implement ``bounds``; the built-in limits also implement ``stacked`` directly (the hot path).

    Attributes:
        name: Short name, used in ``Problem.relaxations``.
        priority: Lower is harder; see the module docstring for the order.
        needs_free_velocity: Whether ``bounds`` reads ``ctx.v_free``.
        objective_scale: Factor in (0, 1] for the objective's linear term, set by ``bounds`` (1 by default).
    """

    name: str = "limit"
    priority: int = 50
    needs_free_velocity: bool = False
    objective_scale: float = 1.0  # factor the builder applies to the linear term after ``bounds``
    _stacked_buffer: np.ndarray | None = None

    @abc.abstractmethod
    def bounds(self, ctx: StepContext) -> tuple[np.ndarray, np.ndarray]:
        """Velocity bounds (lower, upper) [rad/s], each (nv,); ±inf where unbounded. Buffers may be re-used."""

    def stacked(self, ctx: StepContext) -> np.ndarray:
        """The bounds as one array (2, nv): ``[upper, -lower]`` [rad/s] (a buffer re-used by the next call)."""
        lower, upper = self.bounds(ctx)
        out = self._stacked_buffer
        if out is None or out.shape[1] != upper.shape[0]:
            out = self._stacked_buffer = np.empty((2, upper.shape[0]))
        out[0] = upper
        np.negative(lower, out=out[1])
        return out


class StackedBoxLimit(BoxLimit):
    """A box limit that computes its stacked bounds directly; ``bounds`` is derived from them."""

    def bounds(self, ctx: StepContext) -> tuple[np.ndarray, np.ndarray]:
        s = self.stacked(ctx)
        return -s[1], s[0].copy()

    @abc.abstractmethod
    def stacked(self, ctx: StepContext) -> np.ndarray:
        """The bounds as one array (2, nv): ``[upper, -lower]`` [rad/s]."""


class RowLimit(abc.ABC):
    """A limit written as soft inequality rows ``G v <= h`` (one slack variable per row).

    Attributes:
        name: Short name.
        max_rows: Most rows it can write.
    """

    name: str = "rows"
    max_rows: int = 0

    @abc.abstractmethod
    def rows(self, ctx: StepContext, G: np.ndarray, h: np.ndarray) -> int:
        """Write up to ``max_rows`` rows into ``G`` (max_rows, nv) and ``h`` (max_rows,); return how many."""


def intersect_relaxed(
    lower: np.ndarray, upper: np.ndarray, new_lower: np.ndarray, new_upper: np.ndarray, scratch: np.ndarray
) -> None:
    """Intersect ``[lower, upper]`` with ``[new_lower, new_upper]`` in place, never emptying it.

    Where the intervals meet, the result is their intersection; where the new one lies entirely above (below), the
    result is the single point ``upper`` (``lower``), the admissible value closest to it. Requires
    ``lower <= upper`` on entry; guarantees it on exit.
    """
    np.maximum(lower, new_lower, out=scratch)
    np.minimum(scratch, upper, out=scratch)
    np.minimum(upper, new_upper, out=upper)
    np.maximum(upper, lower, out=upper)
    lower[:] = scratch


def intersect_stacked(box: np.ndarray, new: np.ndarray, scratch: np.ndarray) -> None:
    """:func:`intersect_relaxed` on stacked boxes (2, nv) ``[upper, -lower]``, in place (three operations).

    ``new upper = max(min(upper, new_upper), lower)`` and ``new lower = min(max(lower, new_lower), upper)``, both
    from the old box: in stacked form ``box = max(min(box, new), -box[::-1])``.
    """
    np.negative(box[::-1], out=scratch)
    np.minimum(box, new, out=box)
    np.maximum(box, scratch, out=box)
