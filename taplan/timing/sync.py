"""Dual-arm (multi-group) synchronisation: one time base for several joint groups, or independent timings.

``synchronise`` retimes the groups' waypoints together (one path in the joint space of all groups, so they start and
arrive together and every intermediate waypoint is reached at the same instant), or each group on its own (each with its
own, time-optimal duration; a trajectory holds its final position after its end when evaluated later).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from taplan.errors import InvalidInputError
from taplan.limits import JointLimits
from taplan.timing.path import validate_waypoints
from taplan.timing.toppra_retime import retime
from taplan.trajectory import Trajectory

__all__ = ["synchronise", "split", "MODES"]

MODES = ("together", "independent")


def synchronise(
    waypoints: Mapping[str, npt.ArrayLike],
    limits: Mapping[str, JointLimits],
    *,
    mode: str = "together",
    jerk: bool = False,
) -> dict[str, Trajectory]:
    """Time several groups' waypoints (e.g. ``{"left": ..., "right": ...}``).

    Args:
        waypoints: Group name -> waypoints [rad], shape (N, n_group). In ``"together"`` mode every group needs the
            same N (waypoint k of every group is reached at the same time).
        limits: Group name -> that group's JointLimits (e.g. ``robot.planning_limits.subset(group.joint_names)``).
        mode: ``"together"``: one TOPP-RA timing of the combined path (same start, same arrival, same waypoint
            times); ``"independent"``: each group time-optimal on its own.
        jerk: Use the jerk-limited method instead of plain TOPP-RA.

    Returns:
        Group name -> trajectory (starting at t = 0). In ``"together"`` mode all share the same sample times.

    Raises:
        InvalidInputError: unknown mode, mismatched groups or waypoint counts. TimingError: no feasible timing.
    """
    if mode not in MODES:
        raise InvalidInputError("mode", mode, f"one of {MODES}")
    names = list(waypoints)
    if not names or set(names) != set(limits):
        raise InvalidInputError("limits", sorted(limits), f"limits for exactly the groups {sorted(names)}")
    arrays = {g: validate_waypoints(waypoints[g], f"waypoints[{g!r}]", limits[g].size) for g in names}
    if mode == "independent":
        return {g: _time(arrays[g], limits[g], jerk) for g in names}
    counts = {g: a.shape[0] for g, a in arrays.items()}
    if len(set(counts.values())) != 1:
        raise InvalidInputError("waypoints", counts, "the same number of waypoints for every group in 'together' mode")
    combined_limits = JointLimits(
        tuple(n for g in names for n in limits[g].names),
        *(np.concatenate([getattr(limits[g], f) for g in names]) for f in ("lower", "upper")),
        *(np.concatenate([getattr(limits[g], f) for g in names]) for f in ("velocity", "acceleration", "jerk")),
    )
    q = np.hstack([arrays[g] for g in names])
    traj = _time(q, combined_limits, jerk)
    return split(traj, {g: limits[g].names for g in names})


def _time(q: np.ndarray, limits: JointLimits, jerk: bool) -> Trajectory:
    if jerk:
        from taplan.timing.jerk_limited import jerk_limited

        return jerk_limited(q, limits).trajectory
    return retime(q, limits)


def split(traj: Trajectory, groups: Mapping[str, tuple[str, ...]]) -> dict[str, Trajectory]:
    """One trajectory per group (same times), from a trajectory over all their joints."""
    return {g: traj.select(list(joints)) for g, joints in groups.items()}
