"""Waypoint input normalisation shared by the controller models."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from taplan._validation import as_positive, as_vector
from taplan.errors import InvalidInputError
from taplan.trajectory import Trajectory, Waypoint

WaypointsLike = Trajectory | Sequence[Waypoint]


@dataclass(frozen=True)
class WaypointArrays:
    """Waypoints as arrays. Missing fields of a point are NaN rows with ``has_*[i] = False``."""

    times: np.ndarray  # (N,) time_from_start [s]
    positions: np.ndarray  # (N, n)
    velocities: np.ndarray  # (N, n)
    accelerations: np.ndarray  # (N, n)
    has_velocities: np.ndarray  # (N,) bool
    has_accelerations: np.ndarray  # (N,) bool
    joint_names: tuple[str, ...]

    @property
    def size(self) -> int:
        return int(self.times.shape[0])

    @property
    def n_joints(self) -> int:
        return int(self.positions.shape[1])


def waypoint_arrays(waypoints: WaypointsLike, joint_names: Sequence[str] | None = None) -> WaypointArrays:
    """Validate and stack waypoints (a :class:`Trajectory` gives the fields it stores, times from ``times[0]``)."""
    if isinstance(waypoints, Trajectory):
        t = np.asarray(waypoints.times - waypoints.times[0], dtype=float)
        q = np.asarray(waypoints.positions, dtype=float)
        n = q.shape[1]
        nan = np.full_like(q, np.nan)
        v = nan if waypoints.velocities is None else np.asarray(waypoints.velocities, dtype=float)
        a = nan if waypoints.accelerations is None else np.asarray(waypoints.accelerations, dtype=float)
        hv = np.full(len(t), waypoints.velocities is not None)
        ha = np.full(len(t), waypoints.accelerations is not None)
        names = tuple(joint_names) if joint_names is not None else waypoints.joint_names
        if len(names) != n:
            raise InvalidInputError("joint_names", names, f"{n} names")
        return WaypointArrays(t, q, v, a, hv, ha, names)
    try:
        points = list(waypoints)
    except TypeError:
        raise InvalidInputError("waypoints", waypoints, "a Trajectory or a sequence of Waypoint") from None
    if not points:
        raise InvalidInputError("waypoints", "an empty sequence", "at least one waypoint")
    first = points[0]
    if not isinstance(first, Waypoint):
        raise InvalidInputError("waypoints[0]", first, "a taplan.trajectory.Waypoint")
    n = np.asarray(first.positions).size
    if n == 0:
        raise InvalidInputError("waypoints[0].positions", first.positions, "at least one joint")
    N = len(points)
    t = np.empty(N)
    q = np.empty((N, n))
    v = np.full((N, n), np.nan)
    a = np.full((N, n), np.nan)
    hv = np.zeros(N, dtype=bool)
    ha = np.zeros(N, dtype=bool)
    for i, w in enumerate(points):
        if not isinstance(w, Waypoint):
            raise InvalidInputError(f"waypoints[{i}]", w, "a taplan.trajectory.Waypoint")
        tf = float(w.time_from_start)
        if not np.isfinite(tf) or tf < 0:
            raise InvalidInputError(f"waypoints[{i}].time_from_start", w.time_from_start, "a finite time >= 0 [s]")
        t[i] = tf
        q[i] = as_vector(w.positions, f"waypoints[{i}].positions", n)
        if w.velocities is not None and np.asarray(w.velocities).size:
            v[i] = as_vector(w.velocities, f"waypoints[{i}].velocities", n)
            hv[i] = True
        if w.accelerations is not None and np.asarray(w.accelerations).size:
            a[i] = as_vector(w.accelerations, f"waypoints[{i}].accelerations", n)
            ha[i] = True
    names = tuple(joint_names) if joint_names is not None else tuple(f"joint{i}" for i in range(n))
    if len(names) != n or len(set(names)) != n:
        raise InvalidInputError("joint_names", names, f"{n} unique names")
    return WaypointArrays(t, q, v, a, hv, ha, names)


def initial_state(value: npt.ArrayLike | None, default: np.ndarray, n: int) -> np.ndarray:
    return np.array(default, dtype=float) if value is None else as_vector(value, "initial_positions", n).copy()


def rate(value: float, name: str) -> float:
    return as_positive(value, name)
