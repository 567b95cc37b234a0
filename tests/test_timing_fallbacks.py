"""plan_motion's timing fallbacks: computed only when their duration floor says they could be the shortest."""

from __future__ import annotations

import importlib

import numpy as np

import taplan
from benchmarks._scenes import problems
from taplan.planning import motion, plan_motion
from taplan.scene import CollisionWorld


def test_fallbacks_that_cannot_be_shortest_are_not_computed_and_the_plan_is_the_same(monkeypatch) -> None:
    """Clutter #4 of the benchmark: its fastest timing comes too close to a box, and the fallback that verifies
    (1.85 s) is shorter than the floors of the slowed ones (rest-to-rest at half and a quarter of the limits: 1.9
    and 2.6 s). They are not computed; the plan is the one computing every fallback gives, bit for bit."""
    robot = taplan.Robot.teleavatar()
    problem = problems(5, 0)[4]
    timed: list[float] = []
    original = motion._duration_floor
    module = importlib.import_module("taplan.timing.jerk_limited")
    calls: list[int] = []
    jerk_limited = module.jerk_limited

    def counting(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        calls[-1] += 1
        return jerk_limited(*args, **kwargs)

    monkeypatch.setattr(module, "jerk_limited", counting)

    def plan(floor) -> taplan.Trajectory:  # noqa: ANN001
        monkeypatch.setattr(motion, "_duration_floor", floor)
        timed.clear()
        calls.append(0)
        world = CollisionWorld(robot, problem.scene)
        result = plan_motion(robot, problem.start, problem.goal, world=world, max_time=30.0, seed=problem.index)
        assert result.report.timing_fallback.startswith("timing fell back to")
        return result.trajectory

    def counted(*args):  # noqa: ANN002, ANN202
        timed.append(original(*args))
        return timed[-1]

    lazy = plan(counted)
    floors = sorted(timed)
    every = plan(lambda *args: 0.0)  # no floor rules a fallback out: every one is computed, as before
    assert floors[-1] > lazy.duration  # [s] a slowed timing ruled out by its floor
    assert calls[0] < calls[1]  # fewer timings computed (2 against 4)
    assert lazy.duration == every.duration
    t = np.linspace(0.0, lazy.duration, 200)
    np.testing.assert_array_equal(lazy(t), every(t))
