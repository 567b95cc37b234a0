"""The time-optimal jerk-limited rest-to-rest motion along a straight joint-space segment (ruckig).

With phase synchronisation every joint's profile is the same scaled profile, so the motion stays exactly on the
segment ``q(t) = a + (b − a) s(t)``; ruckig makes it the fastest such motion under the per-joint velocity,
acceleration and jerk limits. Its duration is the TOPP-RA optimum plus about ``a/j`` (one jerk ramp), where the
moving-average filter of :func:`~taplan.timing.jerk_limited.jerk_limited` adds ``2a/j``.

The ruckig trajectory is converted exactly: between its phase switches the jerk is constant, so each piece is the
cubic through the position, velocity and acceleration ruckig reports at the piece's start.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import ruckig

from taplan._validation import as_vector
from taplan.errors import InvalidInputError, TimingError
from taplan.limits import JointLimits
from taplan.trajectory import Trajectory

__all__ = ["straight_line"]

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
    generator = ruckig.Ruckig(n)
    request = ruckig.InputParameter(n)
    request.current_position = a.tolist()
    request.target_position = b.tolist()
    request.current_velocity = request.current_acceleration = [0.0] * n
    request.target_velocity = request.target_acceleration = [0.0] * n
    request.max_velocity = limits.velocity.tolist()
    request.max_acceleration = limits.acceleration.tolist()
    request.max_jerk = limits.jerk.tolist()
    request.synchronization = ruckig.Synchronization.Phase
    motion = ruckig.Trajectory(n)
    try:
        result = generator.calculate(request, motion)
    except RuntimeError as exc:
        raise TimingError(f"ruckig: {exc}") from exc
    if result not in (ruckig.Result.Working, ruckig.Result.Finished):
        raise TimingError(f"ruckig found no straight-line motion ({result.name})")
    switches = [0.0, motion.duration]
    for profile in motion.profiles[0]:
        switches += np.cumsum(profile.t).tolist()
    times = np.unique(np.clip(switches, 0.0, motion.duration))
    times = times[np.concatenate([[True], np.diff(times) > _SWITCH_TOL])]
    times[-1] = motion.duration
    states = [motion.at_time(float(t)) for t in times]
    coefficients = np.zeros((len(times) - 1, 4, n))
    for k, dt in enumerate(np.diff(times)):
        p, v, acc = (np.asarray(x, dtype=float) for x in states[k])
        jerk = (np.asarray(states[k + 1][2], dtype=float) - acc) / dt
        coefficients[k] = [p, v, acc / 2, jerk / 6]
    trajectory = Trajectory.from_polynomials(times - times[0], coefficients, limits.names)
    if not np.allclose(trajectory(trajectory.duration), b, atol=1e-7):
        raise TimingError("ruckig's straight-line motion does not end at the goal")
    return trajectory
