"""Adapter to ruckig's online interface: owns one Ruckig instance and re-uses its input and output objects.

Every ruckig failure (a ``RuckigError`` exception or a negative ``Result``) becomes a :class:`~taplan.StreamError`
here, so the streamers never see ruckig's types. Pitfalls handled here:

* ``InputParameter`` fields are copied on read and write (``inp.target_position[0] = x`` is lost): always assign
  whole lists.
* ``Ruckig.update`` recomputes only when the input differs from the one it stored; ``pass_to_input`` keeps them
  equal, so following a trajectory costs about a microsecond per cycle.
* ``min_position`` / ``max_position`` are ignored by the free version, and ``trajectory.position_extrema`` misses
  extrema inside constant-acceleration segments: :meth:`RuckigAdapter.leaves_bounds` checks each new trajectory
  completely.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
import ruckig

from taplan.errors import StreamError
from taplan.limits import JointLimits
from taplan.stream.safety import stop_excursion

__all__: list[str] = []

_RESULT_NAMES = {int(r): r.name for r in ruckig.Result.__members__.values()}
_SYNCHRONIZATION = {
    "time": ruckig.Synchronization.Time,
    "phase": ruckig.Synchronization.Phase,
    "none": ruckig.Synchronization.No,
}
_BRAKE = "brake"  # (the velocity interface, not a synchronization name)
WORKING = int(ruckig.Result.Working)
FINISHED = int(ruckig.Result.Finished)


class RuckigAdapter:
    """One online ruckig generator for ``limits.size`` degrees of freedom at period ``dt``."""

    def __init__(self, limits: JointLimits, dt: float) -> None:
        n = limits.size
        self.n = n
        self.dt = dt
        self.otg = ruckig.Ruckig(n, dt)
        self.inp = ruckig.InputParameter(n)
        self.out = ruckig.OutputParameter(n)
        self.inp.max_velocity = limits.velocity.tolist()
        self.inp.max_acceleration = limits.acceleration.tolist()
        self.inp.max_jerk = limits.jerk.tolist()
        self._zeros = [0.0] * n
        self._amax = limits.acceleration.tolist()
        self._jmax = limits.jerk.tolist()
        self.inp.target_acceleration = self._zeros  # never changes: every target is at zero acceleration
        self._interface: str | None = None  # last assigned: a position target's synchronization, or _BRAKE
        self._range = range(n)

    def set_state(self, position: list[float], velocity: list[float], acceleration: list[float]) -> None:
        """Overwrite the current state (a reset from a measured state)."""
        self.inp.current_position = position
        self.inp.current_velocity = velocity
        self.inp.current_acceleration = acceleration
        self.otg.reset()

    def set_position_target(self, position: list[float], velocity: list[float], synchronization: str) -> None:
        """Position interface: reach ``position`` with ``velocity`` and zero acceleration."""
        inp = self.inp
        # each assignment crosses into C++ and copies: skip the interface when nothing changes (retargeting)
        if self._interface != synchronization:
            inp.control_interface = ruckig.ControlInterface.Position
            inp.synchronization = _SYNCHRONIZATION[synchronization]
            self._interface = synchronization
        inp.target_position = position
        inp.target_velocity = velocity

    def set_brake(self) -> None:
        """Velocity interface to zero velocity and acceleration: the shortest jerk-limited stop."""
        if self._interface != _BRAKE:
            self.inp.control_interface = ruckig.ControlInterface.Velocity
            self.inp.synchronization = ruckig.Synchronization.No
            self._interface = _BRAKE
        self.inp.target_velocity = self._zeros

    def update(self) -> int:
        """One period of ruckig; returns ``WORKING`` or ``FINISHED``, raises :class:`StreamError` otherwise."""
        try:
            result = self.otg.update(self.inp, self.out)
        except ruckig.RuckigError as exc:
            raise StreamError(f"ruckig rejected the input: {str(exc).strip()}") from None
        code = int(result)
        if code < 0:
            raise StreamError(f"ruckig failed: {_RESULT_NAMES.get(code, code)} ({code})")
        return code

    def set_bounds(self, lower: np.ndarray, upper: np.ndarray, tolerance: float) -> None:
        """Position bounds [rad] (shape (n,)) and their numerical slack [rad] used by :meth:`leaves_bounds`."""
        self._lo = (lower - tolerance).tolist()
        self._hi = (upper + tolerance).tolist()

    def leaves_bounds(self, joints: Iterable[int] | None = None, *, check_end: bool = True) -> bool:
        """True when the new trajectory goes beyond the bounds set by :meth:`set_bounds` (for ``joints``; all).

        ``check_end=False`` skips the end state, for a position target at rest inside the bounds: every joint ends
        and stays on it (a moving target's early joints coast on past their profile, which only the end shows).
        A moving end state must also leave room for the shortest stop from it (:func:`stop_excursion`): without
        synchronisation an early joint coasts at its target velocity until the slowest joint arrives, so the
        admission rule for target velocities (room for one period of coasting past the target) does not cover it.
        The end is checked with that period of coasting as well.

        ruckig's ``position_extrema`` misses an extremum inside a constant-acceleration segment (it looks for interior
        extrema only where the jerk is non-zero) and omits the straight tail of joints that arrive early without
        synchronisation; ``get_first_time_at_position`` can report a crossing that does not exist near a triple root.
        So: a fast screen (end position, reported extrema, then first time at each bound, which finds every crossing
        of a bound since the start is inside), and every joint the screen flags is confirmed on its profile with
        :func:`profile_range` (exact: every segment's turning points). The screen costs about 0.7 [us] per joint.
        """
        trajectory = self.out.trajectory
        lo, hi = self._lo, self._hi
        if check_end:
            end, end_velocity, end_acceleration = trajectory.at_time(trajectory.duration)[:3]
        else:
            end = None
        extrema = trajectory.position_extrema
        first_time = trajectory.get_first_time_at_position
        suspects = []
        for i in self._range if joints is None else joints:
            low, high = lo[i], hi[i]
            if end is not None:
                if not low <= end[i] <= high:
                    return True  # the end state is exact
                if end_velocity[i] != 0.0 or end_acceleration[i] != 0.0:
                    # ruckig reports the end up to one period late, having coasted on at the end velocity
                    speed = end_velocity[i]
                    coast = speed * self.dt
                    down, up = stop_excursion(speed, end_acceleration[i], self._amax[i], self._jmax[i])
                    if end[i] + min(coast, 0.0) + down < low or end[i] + max(coast, 0.0) + up > high:
                        return True
            bound = extrema[i]
            if bound.min < low or bound.max > high or first_time(i, low) is not None or first_time(i, high) is not None:
                suspects.append(i)
        if not suspects:
            return False
        profiles = trajectory.profiles[0]
        for i in suspects:
            low, high = profile_range(profiles[i])
            if low < lo[i] or high > hi[i]:
                return True
        return False

    def duration(self) -> float:
        """Duration of the current trajectory [s]."""
        return float(self.out.trajectory.duration)


def _segments_range(
    t: list[float], j: list[float], a: list[float], v: list[float], p: list[float]
) -> tuple[float, float]:
    """Exact position range of consecutive constant-jerk segments (durations ``t``; start states ``a, v, p``)."""
    low = high = p[0]
    for k in range(len(t)):
        duration = t[k]
        if duration <= 0.0:
            continue
        jk, ak, vk, pk = j[k], a[k], v[k], p[k]
        end = pk + duration * (vk + duration * (ak / 2.0 + duration * jk / 6.0))
        low, high = min(low, end), max(high, end)
        # turning points: v + a tau + j tau^2 / 2 = 0 inside (0, duration)
        if jk == 0.0:
            roots = (-vk / ak,) if ak != 0.0 else ()
        else:
            disc = ak * ak - 2.0 * jk * vk
            if disc < 0.0:
                continue
            root = math.sqrt(disc)
            roots = ((-ak - root) / jk, (-ak + root) / jk)
        for tau in roots:
            if 0.0 < tau < duration:
                x = pk + tau * (vk + tau * (ak / 2.0 + tau * jk / 6.0))
                low, high = min(low, x), max(high, x)
    return low, high


def profile_range(profile: ruckig.Profile) -> tuple[float, float]:
    """Exact (min, max) position [rad] over a ruckig profile, its braking pre-profile included."""
    low, high = _segments_range(profile.t, profile.j, profile.a, profile.v, profile.p)
    brake = profile.brake
    if brake.duration > 0.0:
        b_low, b_high = _segments_range(brake.t, brake.j, brake.a, brake.v, brake.p)
        low, high = min(low, b_low), max(high, b_high)
    return low, high
