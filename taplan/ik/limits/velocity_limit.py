"""Velocity limit: ``|v| <= v_max`` per joint."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from taplan._validation import as_vector
from taplan.errors import InvalidInputError
from taplan.ik.limits.limit import BoxLimit, StepContext

__all__ = ["VelocityLimit"]


class VelocityLimit(BoxLimit):
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
        self._lower = -self.velocity
        self._upper = self.velocity.copy()

    def bounds(self, ctx: StepContext) -> tuple[np.ndarray, np.ndarray]:
        return self._lower, self._upper
