"""Task base class: a least-squares objective on the joint displacement.

A task has an error ``e(q)`` (rows,) that is zero at the goal and its Jacobian ``J = de/dq`` (rows, nv). Its cost in
the QP is ``|| W (J Δq + gain e) ||²`` with ``W = diag(weights)``: a step ``Δq = v dt`` that removes the fraction
``gain`` of the error, to first order.
"""

from __future__ import annotations

import abc

import numpy as np

from taplan.errors import InvalidInputError
from taplan.ik._kinematics import Kinematics

__all__ = ["Task"]


class Task(abc.ABC):
    """A least-squares objective ``|| W (J Δq + gain e) ||²``.

    Attributes:
        rows: Number of error rows.
        gain: Fraction of the error removed per step, in (0, 1].
    """

    rows: int
    gain: float

    @abc.abstractmethod
    def compute_error(self, kin: Kinematics) -> np.ndarray:
        """Task error ``e(q)`` at the configuration held by ``kin``. Shape (rows,)."""

    @abc.abstractmethod
    def compute_jacobian(self, kin: Kinematics) -> np.ndarray:
        """Jacobian ``de/dq`` at the configuration held by ``kin``. Shape (rows, nv)."""

    @abc.abstractmethod
    def weights(self) -> np.ndarray:
        """Row weights ``W`` (rows,) (square roots of the quadratic costs)."""

    def fill(self, kin: Kinematics, A: np.ndarray, b: np.ndarray) -> None:
        """Write the weighted rows: ``A = W J`` (rows, nv), ``b = -gain W e`` (rows,), in place."""
        w = self.weights()
        np.multiply(w[:, None], self.compute_jacobian(kin), out=A)
        np.multiply(-self.gain * w, self.compute_error(kin), out=b)


def check_gain(gain: float) -> float:
    """Validate a task gain in (0, 1]."""
    gain = float(gain)
    if not (np.isfinite(gain) and 0.0 < gain <= 1.0):
        raise InvalidInputError("gain", gain, "a number in (0, 1]")
    return gain


def check_cost(cost: object, name: str, size: int) -> np.ndarray:
    """Validate a cost: a scalar or a vector of ``size`` non-negative finite numbers; returns shape (size,)."""
    try:
        array = np.asarray(cost, dtype=float)
    except (TypeError, ValueError):
        raise InvalidInputError(name, cost, f"a number or {size} numbers >= 0") from None
    if array.ndim == 0:
        array = np.full(size, float(array))
    if array.shape != (size,) or not np.all(np.isfinite(array)) or np.any(array < 0.0):
        raise InvalidInputError(name, cost, f"a number or {size} finite numbers >= 0")
    return array
