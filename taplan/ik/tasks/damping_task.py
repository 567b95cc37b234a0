"""Damping task: penalise the joint velocity itself (smoothness, regularisation near singularities)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from taplan.ik._kinematics import Kinematics
from taplan.ik.tasks.task import Task, check_cost

__all__ = ["DampingTask"]


class DampingTask(Task):
    """Cost ``|| W Δq ||²``: error zero, Jacobian identity. Cost per [rad] of displacement (number or (nv,)).

    Unlike the posture task it has no reference: it only resists motion, like Levenberg-Marquardt damping.
    """

    def __init__(self, nv: int, cost: npt.ArrayLike = 1e-3) -> None:
        self.rows = int(nv)
        self.gain = 1.0
        self._weights = check_cost(cost, "damping_cost", self.rows)
        self._written: np.ndarray | None = None

    def weights(self) -> np.ndarray:
        return self._weights

    def compute_error(self, kin: Kinematics) -> np.ndarray:
        return np.zeros(self.rows)

    def compute_jacobian(self, kin: Kinematics) -> np.ndarray:
        return np.eye(self.rows)

    def fill(self, kin: Kinematics, A: np.ndarray, b: np.ndarray) -> None:
        if A is not self._written:  # constant rows: written once per (re-used) buffer
            A[:] = np.diag(self._weights)
            b[:] = 0.0
            self._written = A
