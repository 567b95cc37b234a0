"""plan_motion's goal IK (motion._goal_ik): one short attempt per seed first, stopped once a clear solution is in hand
and three seeds were tried; restarts only when every seed failed. The goals reached meet the targets and keep the
margin."""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np
import pytest

import taplan
from benchmarks._scenes import problems
from taplan.planning import motion
from taplan.scene import CollisionWorld

MARGIN, FLOOR = 0.01, 0.0025  # [m] plan_motion's defaults
POSITION_TOL, ORIENTATION_TOL = 1e-3, 1e-2  # [m], [rad]: solve_pose's default tolerance
SOLVE_POSE = sys.modules["taplan.ik.solve_pose"]


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


@pytest.fixture(scope="module")
def divider() -> Any:
    """Problem 10 of the benchmark's 39: both hands beside a divider; the start seed's IK does not converge."""
    problem = problems(11, 0)[10]
    assert problem.family == "divider" and isinstance(problem.goal, dict)
    return problem


def _spy(monkeypatch: pytest.MonkeyPatch, fail_without_restarts: bool = False) -> list[dict[str, Any]]:
    calls: list[dict[str, Any]] = []
    solve = SOLVE_POSE.solve_pose

    def spy(robot: taplan.Robot, targets: Any, q0: Any, **kwargs: Any) -> Any:
        result = solve(robot, targets, q0, **kwargs)
        if fail_without_restarts and kwargs["restarts"] == 0:
            result.success = False
        calls.append({**kwargs, "success": result.success})
        return result

    monkeypatch.setattr(SOLVE_POSE, "solve_pose", spy)
    return calls


def _goal(robot: taplan.Robot, problem: Any, seed: int = 0) -> np.ndarray:
    world = CollisionWorld(robot, problem.scene)
    rng = np.random.default_rng(seed)
    return motion._goal_ik(
        robot, world, problem.goal, problem.start, robot.planning_limits, MARGIN, FLOOR, 6, rng, time.perf_counter() + 5
    )


def _assert_reaches(robot: taplan.Robot, problem: Any, q: np.ndarray) -> None:
    for frame, target in problem.goal.items():
        pose = robot.frame_pose(q, frame)
        assert np.linalg.norm(pose[:3, 3] - target[:3, 3]) <= POSITION_TOL
        angle = np.arccos(np.clip((np.trace(pose[:3, :3].T @ target[:3, :3]) - 1) / 2, -1.0, 1.0))
        assert angle <= ORIENTATION_TOL
    assert CollisionWorld(robot, problem.scene).min_distance(q)[0] >= MARGIN
    assert robot.planning_limits.within(q)


def test_first_round_gives_each_seed_one_short_attempt_and_stops_after_three_seeds(
    robot: taplan.Robot, divider: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls = _spy(monkeypatch)
    q = _goal(robot, divider)
    _assert_reaches(robot, divider, q)
    assert all(c["restarts"] == 0 and c["max_iterations"] == motion.GOAL_IK_ITERATIONS for c in calls)
    assert [c["seed"] for c in calls] == list(range(len(calls)))
    first_success = next(k for k, c in enumerate(calls) if c["success"])
    assert not calls[0]["success"]  # the start seed does not converge on this goal
    assert len(calls) <= max(motion.GOAL_IK_SEEDS, first_success + 1)


def test_restarts_only_when_every_seed_failed_its_short_attempt(
    robot: taplan.Robot, divider: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls = _spy(monkeypatch, fail_without_restarts=True)
    q = _goal(robot, divider)
    _assert_reaches(robot, divider, q)
    seeds = 2 + 6  # start, home and ik_seeds random configurations
    assert [c["restarts"] for c in calls[:seeds]] == [0] * seeds
    assert calls[seeds:] and all(c["restarts"] == motion.GOAL_IK_RESTARTS for c in calls[seeds:])
    assert all(c["max_iterations"] == 100 for c in calls[seeds:])


def test_a_clear_solution_from_the_start_seed_is_one_solve(
    robot: taplan.Robot, monkeypatch: pytest.MonkeyPatch
) -> None:
    goal_q = robot.home.copy()
    goal_q[robot.group("left").indices[[1, 3]]] += [0.2, -0.3]
    problem = type("P", (), {})()
    problem.scene, problem.start = taplan.scene.Scene(), robot.home
    problem.goal = {"left_tcp": robot.frame_pose(goal_q, "left_tcp")}
    calls = _spy(monkeypatch)
    q = _goal(robot, problem)
    _assert_reaches(robot, problem, q)
    assert len(calls) == 1 and calls[0]["seed"] == 0


def test_a_solution_inside_the_margin_is_taken_only_with_a_certified_approach(robot: taplan.Robot) -> None:
    """Problem 65 of the hard families (seed 1): an IK solution 3.2 mm from the shoulders had no certified approach
    and plan_motion raised; the goal IK now skips such solutions, and the plan reaches the target."""
    hard = ("window", "overhang", "cabinet", "poles", "chest_box", "divider", "attached", "cubby")
    problem = problems(80, 1, hard)[65]
    world = CollisionWorld(robot, problem.scene)
    q = _goal(robot, problem, seed=65)
    d = world.min_distance(q)[0]
    assert d >= FLOOR
    if d < MARGIN:  # [m] inside the margin: only with the segment the plan will follow
        active = np.flatnonzero(np.abs(q - problem.start) > 1e-12)
        limits = robot.planning_limits
        assert motion.approach_segment(world, q, "goal", active, limits.lower, limits.upper, MARGIN, FLOOR)
    plan = motion.plan_motion(robot, problem.start, problem.goal, world=world, max_time=5.0, seed=65)
    for frame, target in problem.goal.items():  # [m] the timed trajectory ends on the targets
        assert np.linalg.norm(robot.frame_pose(plan.path[-1], frame)[:3, 3] - target[:3, 3]) <= POSITION_TOL


def test_near_solutions_without_an_approach_are_skipped(robot: taplan.Robot, monkeypatch: pytest.MonkeyPatch) -> None:
    near = [(0.1, np.full(robot.nq, 1.0)), (0.2, np.full(robot.nq, 2.0))]
    tried: list[float] = []

    def approach(world: Any, q: np.ndarray, *args: Any) -> Any:
        tried.append(float(q[0]))
        return None if q[0] == 1.0 else object()

    monkeypatch.setattr(motion, "approach_segment", approach)
    world = CollisionWorld(robot)
    chosen = motion._approached(world, near, robot.home, robot.planning_limits, MARGIN, FLOOR)
    assert chosen is not None and chosen[0] == 2.0 and tried == [1.0, 2.0]
    monkeypatch.setattr(motion, "approach_segment", lambda *args: None)
    assert motion._approached(world, near, robot.home, robot.planning_limits, MARGIN, FLOOR) is None
