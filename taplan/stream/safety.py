"""Safety rules of the streamers: braking distance, target admission and the no-target watchdog.

Position bounds are taplan's job, not ruckig's: the free ruckig ignores ``min_position`` / ``max_position``. The
streamers keep this invariant: *every emitted state either lies on a trajectory whose whole position range was
checked against the bounds and that ends at rest or at a target state whose stop (after one period of coasting) is
inside the bounds, or is the first period of a new trajectory, inside the bounds with its own shortest stop
(:func:`stop_excursion`) inside them; such a trajectory is checked whole before a second period of it is emitted,
and replaced from that vouched-for state when it fails*. From a state on a checked trajectory the shortest
jerk-limited stop (what a timeout triggers) stops before the first turning point of that trajectory, so it is inside
the bounds too; from a vouched-for state it is inside them by construction. A stream that retargets every period
therefore never pays for the whole-trajectory check.

The braking distance from velocity :math:`v` at zero acceleration with limits :math:`a, j` is

.. math::

    d(v) = \\begin{cases} |v|^{3/2} / \\sqrt{j} & |v| \\le a^2 / j \\\\
                          \\frac{|v|}{2}\\left(\\frac{a}{j} + \\frac{|v|}{a}\\right) & \\text{otherwise} \\end{cases}

(a triangular or trapezoidal deceleration; the velocity profile is point-symmetric, so the mean velocity is
:math:`v/2`).

From a moving state :math:`(v, a)` the stop that a timeout triggers is ruckig's velocity interface to
:math:`(0, 0)` without synchronisation: the time-optimal jerk bang-bang profile. :func:`stopping_range` gives its
position range in closed form (see :func:`stop_excursion`); the joint streamer uses it to vouch for a state emitted
from a new trajectory's first period without checking the whole trajectory.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = ["braking_distance", "max_safe_velocity", "stopping_range", "stop_excursion", "Watchdog"]


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


def stop_excursion(v: float, a: float, amax: float, jmax: float) -> tuple[float, float]:
    """Position range (min, max) [rad], relative to the start, of the time-optimal jerk-limited stop from (v, a).

    The stop reaches velocity and acceleration zero (ruckig's velocity interface, no synchronisation). Let
    :math:`v_0 = v + a|a|/(2j)` be the velocity once the acceleration alone is brought to zero. For
    :math:`v_0 \\ge 0` the profile is jerk :math:`-j` from :math:`a` down to :math:`-p`, a hold at :math:`-p`, jerk
    :math:`+j` back to zero, with :math:`p^2 = a^2/2 + j v` (a triangle; the hold lasts 0) or :math:`p` the
    acceleration limit (a trapezoid, hold :math:`(v + (a^2 - 2p^2)/(2j))/p`). Once the acceleration is <= 0 it stays
    so and the velocity falls monotonically to 0, so the velocity is >= 0 from then on: the maximum is the final
    position (or the start), and the minimum is the start, or, when :math:`v < 0` (then :math:`a > 0`), the point
    where the velocity first crosses zero, :math:`\\tau = (a - \\sqrt{a^2 + 2 j v})/j`. :math:`v_0 < 0` is the
    mirror image. The state must be one ruckig keeps inside its limits (:math:`|a| \\le` ``amax``, no unavoidable
    velocity overshoot).

    Args:
        v: Velocity [rad]/[s].
        a: Acceleration [rad]/[s]², ``|a| <= amax``.
        amax: Acceleration limit [rad]/[s]², > 0.
        jmax: Jerk limit [rad]/[s]³, > 0.

    Returns:
        (lowest, highest) displacement [rad] over the stop; lowest <= 0 <= highest.
    """
    if v + a * abs(a) / (2.0 * jmax) < 0.0:
        low, high = stop_excursion(-v, -a, amax, jmax)
        return -high, -low
    peak2 = 0.5 * a * a + jmax * v
    if peak2 <= amax * amax:
        peak = math.sqrt(max(peak2, 0.0))  # >= 0 but for rounding at v = -a^2 / (2 j) (the mirror test's edge)
        t2 = 0.0
    else:
        peak = amax
        t2 = max(0.0, (v + (a * a - 2.0 * amax * amax) / (2.0 * jmax)) / amax)
    t1 = max(0.0, (a + peak) / jmax)
    t3 = peak / jmax
    # segment 1 (jerk -j), 2 (acceleration -peak), 3 (jerk +j)
    p = t1 * (v + t1 * (0.5 * a - t1 * jmax / 6.0))
    w = v + t1 * (a - 0.5 * jmax * t1)
    p += t2 * (w - 0.5 * peak * t2)
    w -= peak * t2
    p += t3 * (w + t3 * (-0.5 * peak + t3 * jmax / 6.0))
    low = 0.0
    if v < 0.0:  # a > 0 here: the velocity rises through zero during segment 1
        tau = (a - math.sqrt(max(0.0, a * a + 2.0 * jmax * v))) / jmax
        low = min(0.0, tau * (v + tau * (0.5 * a - tau * jmax / 6.0)))
    return low, max(0.0, p)


def stopping_range(
    velocity: npt.ArrayLike,
    acceleration: npt.ArrayLike,
    acceleration_limit: npt.ArrayLike,
    jerk_limit: npt.ArrayLike,
) -> tuple[np.ndarray, np.ndarray]:
    """Per joint, the position range of the shortest jerk-limited stop from a moving state (:func:`stop_excursion`).

    Args:
        velocity: Velocity [rad]/[s]. Shape (n,).
        acceleration: Acceleration [rad]/[s]², within the limit. Shape (n,).
        acceleration_limit: Maximum acceleration [rad]/[s]², > 0. Shape (n,).
        jerk_limit: Maximum jerk [rad]/[s]³, > 0. Shape (n,).

    Returns:
        (lowest, highest) displacement [rad] relative to the current position, shape (n,) each.
    """
    rows = [
        stop_excursion(v, a, amax, jmax)
        for v, a, amax, jmax in zip(
            np.atleast_1d(np.asarray(velocity, dtype=float)).tolist(),
            np.atleast_1d(np.asarray(acceleration, dtype=float)).tolist(),
            np.atleast_1d(np.asarray(acceleration_limit, dtype=float)).tolist(),
            np.atleast_1d(np.asarray(jerk_limit, dtype=float)).tolist(),
            strict=True,
        )
    ]
    low, high = np.array(rows).reshape(-1, 2).T
    return low, high


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
