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

import numpy as np
import ruckig

from taplan.errors import StreamError
from taplan.limits import JointLimits

__all__: list[str] = []

_RESULT_NAMES = {int(r): r.name for r in ruckig.Result.__members__.values()}
_SYNCHRONIZATION = {
    "time": ruckig.Synchronization.Time,
    "phase": ruckig.Synchronization.Phase,
    "none": ruckig.Synchronization.No,
}
WORKING = int(ruckig.Result.Working)
FINISHED = int(ruckig.Result.Finished)


class RuckigAdapter:
    """One online ruckig generator for ``limits.size`` degrees of freedom at period ``dt``."""

    def __init__(self, limits: JointLimits, dt: float) -> None:
        n = limits.size
        self.n = n
        self.otg = ruckig.Ruckig(n, dt)
        self.inp = ruckig.InputParameter(n)
        self.out = ruckig.OutputParameter(n)
        self.inp.max_velocity = limits.velocity.tolist()
        self.inp.max_acceleration = limits.acceleration.tolist()
        self.inp.max_jerk = limits.jerk.tolist()
        self._zeros = [0.0] * n

    def set_state(self, position: list[float], velocity: list[float], acceleration: list[float]) -> None:
        """Overwrite the current state (a reset from a measured state)."""
        self.inp.current_position = position
        self.inp.current_velocity = velocity
        self.inp.current_acceleration = acceleration
        self.otg.reset()

    def set_position_target(self, position: list[float], velocity: list[float], synchronization: str) -> None:
        """Position interface: reach ``position`` with ``velocity`` and zero acceleration."""
        inp = self.inp
        inp.control_interface = ruckig.ControlInterface.Position
        inp.synchronization = _SYNCHRONIZATION[synchronization]
        inp.target_position = position
        inp.target_velocity = velocity
        inp.target_acceleration = self._zeros

    def set_brake(self) -> None:
        """Velocity interface to zero velocity and acceleration: the shortest jerk-limited stop."""
        inp = self.inp
        inp.control_interface = ruckig.ControlInterface.Velocity
        inp.synchronization = ruckig.Synchronization.No
        inp.target_velocity = self._zeros
        inp.target_acceleration = self._zeros

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

    def leaves_bounds(self) -> bool:
        """True when the new trajectory goes beyond the bounds set by :meth:`set_bounds`.

        ruckig's ``position_extrema`` misses an extremum inside a constant-acceleration segment (it looks for interior
        extrema only where the jerk is non-zero), and omits the straight tail of joints that arrive early without
        synchronisation. So three checks: the reported extrema (covering ruckig's braking pre-profile), the end
        position, and ``get_first_time_at_position`` at each bound, which solves every segment's polynomial.
        """
        trajectory = self.out.trajectory
        lo, hi = self._lo, self._hi
        for i, bound in enumerate(trajectory.position_extrema):
            if bound.min < lo[i] or bound.max > hi[i]:
                return True
        end = trajectory.at_time(trajectory.duration)[0]
        first_time = trajectory.get_first_time_at_position
        for i in range(self.n):
            if end[i] < lo[i] or end[i] > hi[i]:
                return True
            if first_time(i, lo[i]) is not None or first_time(i, hi[i]) is not None:
                return True
        return False

    def duration(self) -> float:
        """Duration of the current trajectory [s]."""
        return float(self.out.trajectory.duration)
