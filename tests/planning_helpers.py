"""Problems shared by the planning tests."""

from __future__ import annotations

import numpy as np

import taplan
from taplan.planning import check_segment
from taplan.scene import CollisionWorld


def blocked_problem(robot: taplan.Robot, world: CollisionWorld, margin: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """A left-arm start and goal, both more than 15 mm from everything (the home arms are 19 mm apart), whose
    straight segment ``world`` blocks at ``margin`` [m] (seeded search)."""
    rng = np.random.default_rng(3)
    limits = robot.planning_limits
    idx = robot.group("left").indices
    for _ in range(2000):
        a, b = robot.home.copy(), robot.home.copy()
        a[idx] = limits.lower[idx] + rng.uniform(0.1, 0.9, 7) * (limits.upper[idx] - limits.lower[idx])
        b[idx] = limits.lower[idx] + rng.uniform(0.1, 0.9, 7) * (limits.upper[idx] - limits.lower[idx])
        free = world.min_distance(a)[0] > 0.015 and world.min_distance(b)[0] > 0.015
        if free and not check_segment(world, a, b, margin).valid:
            return a, b
    raise AssertionError("no blocked problem found")
