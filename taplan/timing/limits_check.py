"""How close a trajectory comes to its joint limits, measured exactly on its polynomial segments."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from taplan.errors import InvalidInputError
from taplan.limits import JointLimits
from taplan.timing._polynomial import max_abs_derivative
from taplan.trajectory import Trajectory

__all__ = ["LimitUsage", "limit_usage", "sampled_limit_usage"]


@dataclass(frozen=True)
class LimitUsage:
    """Peak ``|derivative| / limit`` per joint (1.0 = at the limit).

    Attributes:
        velocity: Shape (n,).
        acceleration: Shape (n,).
        jerk: Shape (n,).
        position: Largest excursion outside [lower, upper] [rad] per joint (0 when inside). Shape (n,).
    """

    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray
    position: np.ndarray

    @property
    def max_velocity(self) -> float:
        return float(np.max(self.velocity))

    @property
    def max_acceleration(self) -> float:
        return float(np.max(self.acceleration))

    @property
    def max_jerk(self) -> float:
        return float(np.max(self.jerk))

    def within(self, tolerance: float = 1e-6, *, jerk: bool = False) -> bool:
        """True when velocity and acceleration (and jerk if asked) stay <= 1 + ``tolerance`` of their limits."""
        ok = self.max_velocity <= 1 + tolerance and self.max_acceleration <= 1 + tolerance
        return ok and (not jerk or self.max_jerk <= 1 + tolerance)


def _aligned(traj: Trajectory, limits: JointLimits) -> JointLimits:
    if limits.size != traj.n_joints:
        raise InvalidInputError("limits", f"{limits.size} joints", f"{traj.n_joints} joints, like the trajectory")
    if set(limits.names) == set(traj.joint_names):
        return limits.subset(traj.joint_names)
    return limits


def limit_usage(traj: Trajectory, limits: JointLimits) -> LimitUsage:
    """Exact peaks of velocity, acceleration and jerk over the whole trajectory (every segment's interior extrema).

    Jerk is reported as the peak over segment interiors (a jerk step at a breakpoint is not an impulse).
    """
    lim = _aligned(traj, limits)
    peaks = [max_abs_derivative(traj, order).max(axis=0) for order in (1, 2, 3)]
    pos = _position_excursion(traj, lim)
    return LimitUsage(peaks[0] / lim.velocity, peaks[1] / lim.acceleration, peaks[2] / lim.jerk, pos)


def _position_excursion(traj: Trajectory, lim: JointLimits) -> np.ndarray:
    t = np.linspace(traj.times[0], traj.times[-1], max(2, 20 * len(traj)))
    t = np.union1d(t, traj.times)
    q = traj(t)
    return np.maximum(np.max(q - lim.upper, axis=0), np.max(lim.lower - q, axis=0)).clip(min=0.0)


def sampled_limit_usage(traj: Trajectory, limits: JointLimits, rate: float = 1000.0) -> LimitUsage:
    """Peaks of ``|derivative| / limit`` at uniform samples (``rate`` [Hz]), as a controller would see them.

    Jerk is taken from the trajectory's own third derivative at the samples.
    """
    lim = _aligned(traj, limits)
    t = traj.sample_times(rate)
    peaks = [np.max(np.abs(traj(t, order)), axis=0) for order in (1, 2, 3)]
    q = traj(t)
    pos = np.maximum(np.max(q - lim.upper, axis=0), np.max(lim.lower - q, axis=0)).clip(min=0.0)
    return LimitUsage(peaks[0] / lim.velocity, peaks[1] / lim.acceleration, peaks[2] / lim.jerk, pos)
