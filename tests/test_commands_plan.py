"""`taplan plan`: waypoints from a file -> timed trajectory files within the limits."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from taplan.cli import main

LIMIT_RATIO_TOL = 1e-6  # [-]: sampled peak / limit may exceed 1 by this much


@pytest.fixture
def waypoint_csv(tmp_path, teleavatar, rng):
    names = list(teleavatar.joint_names[:7])
    limits = teleavatar.planning_limits.subset(names)
    waypoints = np.clip(teleavatar.home[:7] + rng.uniform(-0.3, 0.3, (4, 7)), limits.lower, limits.upper)
    path = tmp_path / "left.csv"
    np.savetxt(path, waypoints, delimiter=",", header=",".join(names), comments="")
    return path, names, waypoints, limits


@pytest.mark.parametrize("method", ["topp", "jerk"])
def test_plan_writes_a_trajectory_within_the_planning_limits(waypoint_csv, method, capsys):
    path, names, waypoints, limits = waypoint_csv
    out = path.with_name(f"out_{method}.json")
    assert main(["plan", str(path), "--method", method, "-o", str(out)]) == 0
    assert "PASS" in capsys.readouterr().out
    trajectory = taplan.Trajectory.load(out)
    assert trajectory.joint_names == tuple(names)
    np.testing.assert_allclose(trajectory.positions[0], waypoints[0], atol=1e-9)
    np.testing.assert_allclose(trajectory(trajectory.times[-1]), waypoints[-1], atol=1e-9)
    t = np.arange(0.0, trajectory.duration, 1e-3)
    assert np.all(np.abs(trajectory(t, 1)) <= limits.velocity * (1 + LIMIT_RATIO_TOL))
    assert np.all(np.abs(trajectory(t, 2)) <= limits.acceleration * (1 + LIMIT_RATIO_TOL))
    assert out.with_name(f"{out.stem}_100hz.csv").exists()


def test_plan_rejects_unknown_joints_and_missing_files(tmp_path, capsys):
    path = tmp_path / "bad.csv"
    np.savetxt(path, np.zeros((2, 2)) + [[0.0, 0.1], [0.2, 0.3]], delimiter=",", header="l_joint1,x_joint", comments="")
    assert main(["plan", str(path)]) == 2
    assert "x_joint" in capsys.readouterr().err
    assert main(["plan", str(tmp_path / "none.json")]) == 2
