"""The time-optimal jerk-limited rest-to-rest motion along a straight joint-space segment (ruckig).

With phase synchronisation every joint's profile is the same scaled profile, so the motion stays exactly on the
segment ``q(t) = a + (b − a) s(t)``; ruckig makes it the fastest such motion under the per-joint velocity,
acceleration and jerk limits. Its duration is the TOPP-RA optimum plus about ``a/j`` (one jerk ramp), where the
moving-average filter of :func:`~taplan.timing.jerk_limited.jerk_limited` adds ``2a/j``.

The ruckig trajectory is converted exactly: between its phase switches the jerk is constant, so each piece is the
cubic through the position, velocity and acceleration ruckig reports at the piece's start.
"""

from __future__ import annotations

from math import comb

import numpy as np
import numpy.typing as npt
import ruckig

from taplan._validation import as_vector
from taplan.errors import InvalidInputError, TimingError
from taplan.limits import JointLimits
from taplan.trajectory import Trajectory

__all__ = ["straight_line", "state_to_state", "state_to_state_pieces", "rest_to_rest_time"]

_SWITCH_TOL = 1e-9  # [s] phase switches closer than this are one breakpoint


def straight_line(start: npt.ArrayLike, goal: npt.ArrayLike, limits: JointLimits) -> Trajectory:
    """Rest-to-rest motion from ``start`` to ``goal`` [rad] along the straight segment, time-optimal under the
    velocity, acceleration and jerk ``limits`` (its joints, in its order).

    Raises:
        InvalidInputError: malformed start/goal, or outside the position limits.
        TimingError: ruckig found no trajectory.
    """
    if not isinstance(limits, JointLimits):
        raise InvalidInputError("limits", type(limits).__name__, "a taplan JointLimits")
    n = len(limits.names)
    a = as_vector(start, "start", n)
    b = as_vector(goal, "goal", n)
    for name, q in (("start", a), ("goal", b)):
        if not limits.within(q):
            raise InvalidInputError(name, np.round(q, 6).tolist(), "a configuration within the position limits")
    if np.array_equal(a, b):
        raise InvalidInputError("goal", "the start configuration", "a goal that differs from the start")
    zero = np.zeros(n)
    trajectory = _ruckig_motion((a, zero, zero), (b, zero, zero), limits, ruckig.Synchronization.Phase)
    if not np.allclose(trajectory(trajectory.duration), b, atol=1e-7):
        raise TimingError("ruckig's straight-line motion does not end at the goal")
    return trajectory


def rest_to_rest_time(
    distance: npt.ArrayLike, velocity: npt.ArrayLike, acceleration: npt.ArrayLike, jerk: npt.ArrayLike
) -> np.ndarray:
    """The shortest time [s] of a one-joint motion over ``distance`` [rad] (elementwise, >= 0) from rest to rest
    (zero velocity and acceleration at both ends) within the ``velocity``, ``acceleration`` and ``jerk`` limits:
    the symmetric bang-bang jerk profile, in closed form. Accelerating to a peak speed ``V`` takes
    ``V/a + a/j`` when ``V >= a²/j`` (the acceleration limit reached), else ``2 sqrt(V/j)``, and covers half of
    ``V`` times that; the peak is ``velocity`` when the distance allows it (then a cruise), else the ``V`` whose
    acceleration and deceleration cover the distance. A motion of several joints lasts at least each one's."""
    d, v, a, j = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (distance, velocity, acceleration, jerk)))
    if np.any(d < 0) or np.any(v <= 0) or np.any(a <= 0) or np.any(j <= 0):
        raise InvalidInputError("distance/limits", "a negative distance or a limit <= 0", "distance >= 0, limits > 0")
    corner = a * a / j  # [rad/s] the peak speed from which the acceleration limit is reached

    def ramp(speed: np.ndarray) -> np.ndarray:  # [s] from rest to ``speed`` (and back to zero acceleration)
        return np.where(speed >= corner, speed / a + a / j, 2.0 * np.sqrt(speed / j))

    cruising = d >= v * ramp(v)  # accelerating to the limit and back covers v * ramp(v)
    # below the limit: V ramp(V) = d, with V = a/2 (sqrt((a/j)² + 4 d / a) − a/j) when V >= a²/j, else 2 V^1.5 / sqrt(j)
    high = a / 2 * (np.sqrt((a / j) ** 2 + 4.0 * d / a) - a / j)
    low = np.cbrt((d * np.sqrt(j) / 2.0) ** 2)
    peak = np.where(high >= corner, high, low)
    return np.where(cruising, d / v + ramp(v), 2.0 * ramp(peak))


def state_to_state(
    start: tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike],
    goal: tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike],
    limits: JointLimits,
) -> Trajectory:
    """The time-optimal jerk-limited motion from one state ``(position, velocity, acceleration)`` to another
    (ruckig, every joint arriving together), as exact cubic pieces. The joints move independently in between: the
    motion is not along any given path, and positions are not bounded (check them).

    Raises:
        InvalidInputError: malformed states. TimingError: ruckig found no trajectory, or its pieces do not meet the
            goal state (1e-9).
    """
    return Trajectory.from_polynomials(*state_to_state_pieces(start, goal, limits), limits.names)


def state_to_state_pieces(
    start: tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike],
    goal: tuple[npt.ArrayLike, npt.ArrayLike, npt.ArrayLike],
    limits: JointLimits,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`state_to_state` as ``(times (N,) from 0, coefficients (N-1, 6, n))`` without building a
    :class:`Trajectory` (``jerk_limited`` splices two of these into one trajectory per path)."""
    n = len(limits.names)
    a = tuple(as_vector(x, f"start[{i}]", n) for i, x in enumerate(start))
    b = tuple(as_vector(x, f"goal[{i}]", n) for i, x in enumerate(goal))
    times, coefficients = _ruckig_pieces(a, b, limits, ruckig.Synchronization.Time)
    last, h = coefficients[-1], times[-1] - times[-2]
    end = (  # position, velocity and acceleration at the end of the last piece
        np.polynomial.polynomial.polyval(h, last),
        np.polynomial.polynomial.polyval(h, last[1:] * np.arange(1, 6)[:, None]),
        np.polynomial.polynomial.polyval(h, last[2:] * (np.arange(2, 6) * np.arange(1, 5))[:, None]),
    )
    for k in range(3):
        if not np.allclose(end[k], b[k], atol=1e-9 * max(1.0, float(np.abs(b[k]).max()))):
            raise TimingError("ruckig's state-to-state motion does not end at the goal state")
    return times, coefficients


def _ruckig_motion(
    start: tuple[np.ndarray, ...], goal: tuple[np.ndarray, ...], limits: JointLimits, synchronization: object
) -> Trajectory:
    return Trajectory.from_polynomials(*_ruckig_pieces(start, goal, limits, synchronization), limits.names)


def ruckig_input(start: tuple[np.ndarray, ...], goal: tuple[np.ndarray, ...], limits: JointLimits) -> object:
    """ruckig's input from (position, velocity, acceleration) states and the limits' velocity, acceleration, jerk."""
    request = ruckig.InputParameter(len(limits.names))
    request.current_position, request.current_velocity, request.current_acceleration = (x.tolist() for x in start)
    request.target_position, request.target_velocity, request.target_acceleration = (x.tolist() for x in goal)
    request.max_velocity = limits.velocity.tolist()
    request.max_acceleration = limits.acceleration.tolist()
    request.max_jerk = limits.jerk.tolist()
    return request


def _ruckig_pieces(
    start: tuple[np.ndarray, ...], goal: tuple[np.ndarray, ...], limits: JointLimits, synchronization: object
) -> tuple[np.ndarray, np.ndarray]:
    n = len(limits.names)
    generator = ruckig.Ruckig(n)
    request = ruckig_input(start, goal, limits)
    request.synchronization = synchronization
    motion = ruckig.Trajectory(n)
    try:
        result = generator.calculate(request, motion)
    except (RuntimeError, ruckig.RuckigError) as exc:  # RuckigError: e.g. a target state it cannot reach
        raise TimingError(f"ruckig: {str(exc).strip() or type(exc).__name__}") from exc
    if result not in (ruckig.Result.Working, ruckig.Result.Finished):
        raise TimingError(f"ruckig found no motion ({result.name})")
    switches = [0.0, motion.duration]
    for profile in motion.profiles[0]:  # every joint's phase switches: the jerk is constant in between
        switches += np.cumsum(profile.t).tolist()
    times = np.unique(np.clip(switches, 0.0, motion.duration))
    times = times[np.concatenate([[True], np.diff(times) > _SWITCH_TOL])]
    times[-1] = motion.duration
    accelerations = np.array([motion.at_time(float(t))[2] for t in times], dtype=float)  # (K + 1, n)
    # the pieces are integrated from the start state with ruckig's constant jerk per piece, so they join exactly;
    # the few 1e-12 ruckig's states drift by are removed at the end by a quintic spread over the whole motion. The
    # recurrence state_{k+1} = state_k + increment_k is a running sum (np.cumsum adds in order: the same numbers as
    # a loop over the pieces, without a Python step per piece: ~1 ms less per 14-joint motion of ~60 pieces)
    dt = np.diff(times)[:, None]
    jerk = (accelerations[1:] - accelerations[:-1]) / dt
    acc_all = np.cumsum(np.vstack([start[2][None], dt * jerk]), axis=0)  # at each piece's start, then the end
    acc_k = acc_all[:-1]
    v_all = np.cumsum(np.vstack([start[1][None], dt * (acc_k + dt * jerk / 2)]), axis=0)
    v_k = v_all[:-1]
    p_all = np.cumsum(np.vstack([start[0][None], dt * (v_k + dt * (acc_k / 2 + dt * jerk / 6))]), axis=0)
    coefficients = np.zeros((len(times) - 1, 6, n))
    for power, value in enumerate((p_all[:-1], v_k, acc_k / 2, jerk / 6)):
        coefficients[:, power] = value
    p, v, acc = p_all[-1], v_all[-1], acc_all[-1]
    total = float(times[-1] - times[0])
    e0, e1, e2 = goal[0] - p, goal[1] - v, goal[2] - acc
    top = [  # x³, x⁴, x⁵ coefficients of the correction: zero state at 0, (e0, e1, e2) at ``total``
        (10 * e0 - 4 * e1 * total + 0.5 * e2 * total**2) / total**3,
        (-15 * e0 + 7 * e1 * total - e2 * total**2) / total**4,
        (6 * e0 - 3 * e1 * total + 0.5 * e2 * total**2) / total**5,
    ]
    start_times = times[:-1] - times[0]
    for power, c in zip((3, 4, 5), top, strict=True):  # the correction re-expanded about each piece's start
        for j in range(power + 1):
            coefficients[:, j] += comb(power, j) * (start_times ** (power - j))[:, None] * c[None, :]
    return times - times[0], coefficients
