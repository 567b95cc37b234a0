"""Posture task: pull every joint toward a reference configuration (regularises the redundancy)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from taplan._validation import as_vector
from taplan.ik._kinematics import Kinematics
from taplan.ik.tasks.task import Task, check_cost, check_gain

__all__ = ["PostureTask"]


class PostureTask(Task):
    """Error ``e = q - q_target`` [rad], Jacobian identity; cost per [rad] (a number or per joint (nv,)).

    Args:
        nv: Number of joints.
        cost: Cost per [rad]: a number or (nv,).
        target: Reference configuration [rad], shape (nv,) (default: set later with ``set_target``).
        gain: Fraction of the error removed per step, in (0, 1].
    """

    def __init__(self, nv: int, cost: npt.ArrayLike = 1e-2, target: npt.ArrayLike | None = None, gain: float = 1.0):
        self.rows = int(nv)
        self.gain = check_gain(gain)
        self._weights = check_cost(cost, "posture_cost", self.rows)
        self.target = np.zeros(self.rows) if target is None else as_vector(target, "target", self.rows).copy()
        self._written: np.ndarray | None = None

    def set_target(self, target: npt.ArrayLike) -> None:
        """Reference configuration [rad], shape (nv,)."""
        self.target[:] = as_vector(target, "target", self.rows)

    def set_cost(self, cost: npt.ArrayLike) -> None:
        """Change the cost per [rad] (a number or (nv,))."""
        self._weights = check_cost(cost, "posture_cost", self.rows)
        self._written = None

    def weights(self) -> np.ndarray:
        return self._weights

    def compute_error(self, kin: Kinematics) -> np.ndarray:
        return kin.q - self.target

    def compute_jacobian(self, kin: Kinematics) -> np.ndarray:
        return np.eye(self.rows)

    def fill(self, kin: Kinematics, A: np.ndarray, b: np.ndarray) -> None:
        if A is not self._written:  # constant rows: written once per (re-used) buffer
            A[:] = np.diag(self._weights)
            self._written = A
        np.subtract(self.target, kin.q, out=b)
        b *= self._weights
        if self.gain != 1.0:
            b *= self.gain
