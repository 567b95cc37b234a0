"""Safety rules of the streamers: braking distance, target admission and the no-target watchdog.

Position bounds are taplan's job, not ruckig's: the free ruckig ignores ``min_position`` / ``max_position``. The
streamers keep this invariant: *every emitted state lies on a trajectory whose whole position range was checked
against the bounds and that ends at rest or at a target state whose braking stop is inside the bounds*. From such a
state the shortest jerk-limited stop (what a timeout triggers) stops before the first turning point of that
trajectory, so it is inside the bounds too.

The braking distance from velocity :math:`v` at zero acceleration with limits :math:`a, j` is

.. math::

    d(v) = \\begin{cases} |v|^{3/2} / \\sqrt{j} & |v| \\le a^2 / j \\\\
                          \\frac{|v|}{2}\\left(\\frac{a}{j} + \\frac{|v|}{a}\\right) & \\text{otherwise} \\end{cases}

(a triangular or trapezoidal deceleration; the velocity profile is point-symmetric, so the mean velocity is
:math:`v/2`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["braking_distance", "max_safe_velocity", "Watchdog"]


def braking_distance(
    velocity: npt.ArrayLike, acceleration_limit: npt.ArrayLike, jerk_limit: npt.ArrayLike
) -> np.ndarray:
    """Distance of the shortest jerk-limited stop from ``velocity`` at zero acceleration.

    Args:
        velocity: Velocity [rad]/[s]. Shape (n,).
        acceleration_limit: Maximum acceleration [rad]/[s]², > 0. Shape (n,).
        jerk_limit: Maximum jerk [rad]/[s]³, > 0. Shape (n,).

    Returns:
        Unsigned distance [rad] travelled until rest. Shape (n,).
    """
    v = np.abs(np.asarray(velocity, dtype=float))
    a = np.asarray(acceleration_limit, dtype=float)
    j = np.asarray(jerk_limit, dtype=float)
    triangle = v <= a * a / j
    d_triangle = v * np.sqrt(v / j)
    d_trapezoid = 0.5 * v * (a / j + v / a)
    return np.where(triangle, d_triangle, d_trapezoid)


def max_safe_velocity(room: npt.ArrayLike, acceleration_limit: npt.ArrayLike, jerk_limit: npt.ArrayLike) -> np.ndarray:
    """Largest speed whose braking distance (zero acceleration) fits in ``room``; inverse of :func:`braking_distance`.

    Args:
        room: Distance available [rad], >= 0. Shape (n,).
        acceleration_limit: Maximum acceleration [rad]/[s]². Shape (n,).
        jerk_limit: Maximum jerk [rad]/[s]³. Shape (n,).

    Returns:
        Speed [rad]/[s] >= 0. Shape (n,).
    """
    d = np.maximum(np.asarray(room, dtype=float), 0.0)
    a = np.asarray(acceleration_limit, dtype=float)
    j = np.asarray(jerk_limit, dtype=float)
    v_triangle = np.cbrt(d * d * j)
    # trapezoid: v^2 + v a^2/j - 2 a d = 0
    b = a * a / j
    v_trapezoid = 0.5 * (-b + np.sqrt(b * b + 8.0 * a * d))
    return np.where(v_triangle <= b, v_triangle, v_trapezoid)


class Watchdog:
    """Says when no target has arrived for longer than ``timeout`` (stream time, no wall clock).

    Args:
        timeout: Longest gap between targets [s]; None disables the watchdog.
    """

    def __init__(self, timeout: float | None) -> None:
        self.timeout = timeout
        self._last: float | None = None

    def feed(self, now: float) -> None:
        """A target arrived at ``now`` [s]."""
        self._last = now

    def clear(self) -> None:
        """Forget the last target (e.g. after a reset)."""
        self._last = None

    def expired(self, now: float) -> bool:
        """True when a target was fed and more than ``timeout`` [s] passed since."""
        return self.timeout is not None and self._last is not None and now - self._last > self.timeout + 1e-12
