"""plan_motion runs with one BLAS/OpenMP thread and gives the process its thread settings back (taplan._threads)."""

from __future__ import annotations

import numpy as np
import pytest
import threadpoolctl

import taplan
from taplan._threads import single_threaded
from taplan.planning import motion, plan_motion
from taplan.scene import Box, Scene


def _threads() -> dict[str, int]:
    return {pool["filepath"]: pool["num_threads"] for pool in threadpoolctl.threadpool_info()}


def test_single_threaded_limits_every_pool_and_restores_the_previous_setting() -> None:
    np.ones((4, 4)) @ np.ones((4, 4))  # numpy's BLAS is loaded
    with threadpoolctl.threadpool_limits(limits=2):
        before = _threads()
        assert before and all(n == 2 for n in before.values())
        with single_threaded():
            inside = _threads()
        assert all(inside[path] == 1 for path in before)
        assert _threads() == before
    with threadpoolctl.threadpool_limits(limits=2):  # an exception in the block restores them too
        with pytest.raises(RuntimeError), single_threaded():
            raise RuntimeError("inside")
        assert all(n == 2 for n in _threads().values())


def test_plan_motion_plans_single_threaded_and_restores_the_callers_threads(monkeypatch: pytest.MonkeyPatch) -> None:
    robot = taplan.Robot.teleavatar()
    scene = Scene()
    scene.add("box", Box((0.2, 0.2, 0.2)), pose=([0.6, 0.0, -0.4], [0.0, 0.0, 0.0, 1.0]))
    seen: list[dict[str, int]] = []
    find_path = motion._find_path

    def spy(*args: object, **kwargs: object) -> object:
        seen.append(_threads())
        return find_path(*args, **kwargs)

    monkeypatch.setattr(motion, "_find_path", spy)
    goal = robot.home.copy()
    goal[robot.groups["left"].indices[0]] += 0.3
    with threadpoolctl.threadpool_limits(limits=2):
        before = _threads()
        plan = plan_motion(robot, robot.home, goal, scene, max_time=5.0)
        assert _threads() == before
    assert plan.report.success
    assert seen and all(n == 1 for n in seen[0].values())
