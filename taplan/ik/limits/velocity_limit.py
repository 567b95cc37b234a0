"""Velocity limit: ``|v| <= v_max`` per joint."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from taplan._validation import as_vector
from taplan.errors import InvalidInputError
from taplan.ik.limits.limit import StackedBoxLimit, StepContext

__all__ = ["VelocityLimit"]


class VelocityLimit(StackedBoxLimit):
    """Bound ``-v_max <= v <= v_max``.

    Args:
        velocity: Maximum joint speed [rad/s], shape (nv,), > 0.
    """

    name = "velocity"
    priority = 10

    def __init__(self, velocity: npt.ArrayLike) -> None:
        v = as_vector(velocity, "velocity")
        if np.any(v <= 0.0):
            raise InvalidInputError("velocity", v, "velocity limits > 0 [rad/s]")
        self.velocity = v.copy()
        self._stacked = np.stack([self.velocity, self.velocity])

    def stacked(self, ctx: StepContext) -> np.ndarray:
        return self._stacked
