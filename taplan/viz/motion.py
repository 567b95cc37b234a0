"""A robot's motion as the viewer replays it: every model joint's position, velocity and acceleration at a time.

Two kinds: a :class:`~taplan.trajectory.Trajectory` (evaluated exactly, derivatives from its polynomials) and
recorded samples (a bag's joint streams: positions interpolated linearly, velocities and accelerations by finite
differences of the samples). Joints the motion does not carry hold the robot's home position.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from taplan.errors import InvalidInputError
from taplan.robot import Robot
from taplan.trajectory import Trajectory

__all__ = ["Motion", "joint_index"]


def joint_index(robot: Robot, names: Sequence[str] | None, count: int, what: str = "trajectory") -> np.ndarray:
    """Indices in the robot's joint order of a motion's joints; an error names the joints the model lacks."""
    if names is None:
        if count != robot.nq:
            raise InvalidInputError(
                f"{what} joints", f"{count} unnamed joints", f"joint names, or all {robot.nq} joints of the model"
            )
        return np.arange(robot.nq)
    names = list(names)
    missing = [n for n in names if n not in robot.joint_names]
    if missing:
        raise InvalidInputError(f"{what} joints", missing, f"joints of the model {list(robot.joint_names)}")
    return robot.indices(names)


@dataclass
class Motion:
    """One robot's motion in the viewer.

    Attributes:
        name: Shown in the GUI and used in scene-node names (``/robots/<name>/...``).
        start, end: The time span [s].
        color: RGB of the robot's bodies.
    """

    name: str
    start: float
    end: float
    color: tuple[int, int, int] = (90, 140, 220)
    _hold: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    _index: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]
    _trajectory: Trajectory | None = field(default=None, repr=False)
    _samples: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    @classmethod
    def from_trajectory(
        cls, robot: Robot, trajectory: Trajectory, name: str = "plan", color: tuple[int, int, int] = (90, 140, 220)
    ) -> Motion:
        """The trajectory's joints (by name; all the model's joints when unnamed) over its time span."""
        if not isinstance(trajectory, Trajectory):
            raise InvalidInputError("trajectory", type(trajectory).__name__, "a taplan Trajectory or MotionPlan")
        index = joint_index(robot, trajectory.joint_names, trajectory.n_joints)
        return cls(
            name, float(trajectory.times[0]), float(trajectory.times[-1]), color, robot.home.copy(), index, trajectory
        )

    @classmethod
    def from_samples(
        cls,
        robot: Robot,
        times: np.ndarray,
        positions: np.ndarray,
        joint_names: Sequence[str] | None,
        name: str,
        color: tuple[int, int, int] = (90, 140, 220),
    ) -> Motion:
        """Recorded positions (K, n) at increasing ``times`` (K,) [s]."""
        t = np.asarray(times, dtype=float)
        q = np.asarray(positions, dtype=float)
        if t.ndim != 1 or len(t) < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise InvalidInputError(f"{name} times", t.shape, "at least 2 finite, increasing times [s]")
        if q.shape[0] != len(t) or q.ndim != 2 or not np.all(np.isfinite(q)):
            raise InvalidInputError(f"{name} positions", q.shape, f"({len(t)}, joints) finite positions [rad]")
        index = joint_index(robot, joint_names, q.shape[1], what=name)
        v = np.gradient(q, t, axis=0)
        a = np.gradient(v, t, axis=0)
        return cls(name, float(t[0]), float(t[-1]), color, robot.home.copy(), index, None, (t, q, v, a))

    @property
    def duration(self) -> float:
        return self.end - self.start

    def _clamped(self, t: float) -> float:
        return min(max(float(t), self.start), self.end)

    def joints(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions [rad], velocities [rad/s] and accelerations [rad/s²] of all the model's joints at ``t`` [s]
        (held at the ends outside the span; joints the motion lacks hold home at zero velocity)."""
        t = self._clamped(t)
        q = self._hold.copy()
        v = np.zeros_like(q)
        a = np.zeros_like(q)
        if self._trajectory is not None:
            q[self._index] = self._trajectory(t, 0)
            v[self._index] = self._trajectory(t, 1)
            a[self._index] = self._trajectory(t, 2)
        else:
            times, qs, vs, accs = self._samples  # type: ignore[misc]
            k = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2))
            w = (t - times[k]) / (times[k + 1] - times[k])
            q[self._index] = (1 - w) * qs[k] + w * qs[k + 1]
            v[self._index] = (1 - w) * vs[k] + w * vs[k + 1]
            a[self._index] = (1 - w) * accs[k] + w * accs[k + 1]
        return q, v, a

    def positions(self, times: np.ndarray) -> np.ndarray:
        """All the model's joint positions at several times, shape (len(times), nq)."""
        times = np.asarray(times, dtype=float)
        if self._trajectory is None:
            return np.array([self.joints(t)[0] for t in times])
        q = np.repeat(self._hold[None], len(times), axis=0)
        q[:, self._index] = self._trajectory(np.clip(times, self.start, self.end), 0)
        return q
