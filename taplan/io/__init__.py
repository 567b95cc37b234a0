"""Files in and out: the one trajectory-file contract and the output-path rule every command shares.

* :func:`load_trajectory` / :func:`save_trajectory`: trajectory files (JSON, CSV, NPZ), validated alike whoever
  reads them (``taplan check/plan/replay/run`` and :meth:`taplan.Trajectory.load`); see
  :mod:`taplan.io.trajectory_file` for the contract.
* :func:`read_waypoints`: a waypoint CSV (a header naming the joints, one waypoint per row) or a trajectory file.
* :func:`output_path` / :func:`bounded_rate`: where a command may write, and the range of a ``--rate``.
"""

from taplan.io.paths import MAX_RATE, bounded_rate, output_path
from taplan.io.trajectory_file import (
    ACCELERATION_TOL,
    POSITION_TOL,
    VELOCITY_TOL,
    load_trajectory,
    read_waypoints,
    save_trajectory,
)

__all__ = [
    "ACCELERATION_TOL",
    "MAX_RATE",
    "POSITION_TOL",
    "VELOCITY_TOL",
    "bounded_rate",
    "load_trajectory",
    "output_path",
    "read_waypoints",
    "save_trajectory",
]
