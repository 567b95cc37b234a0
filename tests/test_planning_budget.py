"""plan_motion's margins that bend at the ends (starts and goals inside the margin but clear of the floor) and its
time budget."""

from __future__ import annotations

import time

import numpy as np
import pytest

import taplan
from taplan.errors import CollisionError, InvalidInputError, PlanningError
from taplan.planning import motion, plan_motion
from taplan.scene import Box, CollisionWorld, Scene

# the right arm low in front, beside the box of the table scene (the docs' pose [-0.694, -1.537, 1.399, -1.306,
# -0.263, -0.369, -0.403] puts the upper arm into the shoulder housing and the fingers into the box)
ACROSS = [-0.82, -0.981, 1.206, -1.006, -0.63, -0.196, -0.211]


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _plate_below(robot: taplan.Robot, q: np.ndarray, gap: float) -> CollisionWorld:
    """A 2 cm plate under the right hand at ``q``, moved until its closest robot body is ``gap`` [m] away."""
    scene = Scene()
    p = robot.frame_pose(q, "right_tcp")[:3, 3]
    scene.add("plate", Box((0.3, 0.3, 0.02)), ([p[0], p[1], p[2] - 0.3], [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    for _ in range(4):  # the plate's distance is linear in its height while the same point is closest
        d = world.distances(q, jacobian=False)
        mine = [k for k, pair in enumerate(d.pairs) if pair[1] == "plate"]
        xyz = scene.obstacles["plate"].pose[:3, 3].copy()
        xyz[2] += float(d.distance[mine].min()) - gap
        scene.move("plate", (xyz, [0, 0, 0, 1]))
    return world


def _goal(robot: taplan.Robot) -> np.ndarray:
    q = robot.home.copy()
    q[robot.group("right").indices] = ACROSS
    return q


def _samples(world: CollisionWorld, trajectory: taplan.Trajectory, start: np.ndarray, count: int) -> np.ndarray:
    """Clearance [m] at ``count`` evenly spaced times (an independent sampled check of the certificate)."""
    index = world.robot.indices(trajectory.joint_names)
    out = []
    for t in np.linspace(0.0, trajectory.duration, count):
        q = start.copy()
        q[index] = trajectory(t)
        out.append(world.min_distance(q)[0])
    return np.array(out)


def test_goal_inside_the_margin_is_approached_along_a_certified_segment(robot: taplan.Robot) -> None:
    goal = _goal(robot)
    world = _plate_below(robot, goal, 0.006)  # 6 mm: inside the 10 mm margin, clear of the 2.5 mm floor
    d_goal, pair = world.min_distance(goal)
    assert d_goal == pytest.approx(0.006, abs=1e-6) and pair[1] == "plate"
    plan = plan_motion(robot, robot.home, goal, world=world, max_time=5.0)
    (approach,) = plan.report.approaches
    assert approach.end == "goal" and approach.pair == pair
    assert approach.clearance == pytest.approx(0.006, abs=1e-9)
    assert 0.0025 < approach.certified < 0.006
    assert world.min_distance(approach.clear)[0] >= 0.01  # the segment starts clear of the margin
    assert approach.travel <= 0.08  # short: no robot point moves more than 8 cm along it
    np.testing.assert_allclose(plan.trajectory(plan.trajectory.duration), goal, atol=1e-9)
    clearance = _samples(world, plan.trajectory, robot.home, 600)
    assert clearance.min() >= 0.0025  # nowhere inside the floor
    # the clearance only shrinks along the approach: the last part of the motion, from the clear configuration on
    index = np.flatnonzero(np.linspace(0, 1, 600) * plan.trajectory.duration >= _arrival(plan, approach.clear))
    assert np.all(np.diff(clearance[index]) <= 1e-4)
    assert plan.report.min_clearance <= 0.006 + 1e-9


def _arrival(plan: motion.MotionPlan, q: np.ndarray) -> float:
    """The last time [s] the trajectory passes ``q`` (within 1e-6 rad)."""
    ts = np.linspace(0.0, plan.trajectory.duration, 4001)
    hits = [t for t in ts if np.abs(plan.trajectory(t) - q).max() < 1e-3]
    assert hits, "the trajectory never reaches the approach's clear configuration"
    return float(max(hits))


def test_start_inside_the_margin_is_left_along_a_certified_segment(robot: taplan.Robot) -> None:
    start = _goal(robot)
    world = _plate_below(robot, start, 0.004)
    plan = plan_motion(robot, start, robot.home, world=world, max_time=5.0)
    (approach,) = plan.report.approaches
    assert approach.end == "start" and approach.clearance == pytest.approx(0.004, abs=1e-9)
    np.testing.assert_allclose(plan.trajectory(0.0), start, atol=1e-9)
    assert _samples(world, plan.trajectory, start, 400).min() >= 0.0025


def test_pose_goal_near_a_surface_is_planned_not_refused(robot: taplan.Robot) -> None:
    goal = _goal(robot)
    world = _plate_below(robot, goal, 0.007)
    target = {"right_tcp": robot.frame_pose(goal, "right_tcp")}
    plan = plan_motion(robot, robot.home, target, world=world, max_time=5.0)
    np.testing.assert_allclose(robot.frame_pose(plan.report.goal, "right_tcp"), target["right_tcp"], atol=2e-3)
    assert world.min_distance(plan.report.goal)[0] >= 0.0025
    assert _samples(world, plan.trajectory, robot.home, 300).min() >= 0.0025


def test_goal_inside_the_floor_is_refused_naming_the_pair_and_distance(robot: taplan.Robot) -> None:
    goal = _goal(robot)
    world = _plate_below(robot, goal, 0.0015)
    with pytest.raises(CollisionError, match=r"goal: right_\w+ is 1\.5 mm from plate, inside .* 2\.5 mm") as info:
        plan_motion(robot, robot.home, goal, world=world)
    assert info.value.pair[0].startswith("right_") and info.value.pair[1] == "plate"
    # a lower floor accepts it
    plan = plan_motion(robot, robot.home, goal, world=world, floor=0.001, max_time=5.0)
    assert plan.report.approaches[0].clearance == pytest.approx(0.0015, abs=1e-9)


@pytest.mark.parametrize("floor", [0.0, -0.001, 0.02, float("nan"), "2mm"])
def test_floor_is_validated(robot: taplan.Robot, floor: object) -> None:
    with pytest.raises(InvalidInputError, match="floor"):
        plan_motion(robot, robot.home, _goal(robot), floor=floor)  # type: ignore[arg-type]


@pytest.mark.parametrize("max_time", [0.0, -1.0, float("inf"), None])
def test_max_time_is_validated(robot: taplan.Robot, max_time: object) -> None:
    with pytest.raises(InvalidInputError, match="max_time"):
        plan_motion(robot, robot.home, _goal(robot), max_time=max_time)  # type: ignore[arg-type]


def _hard_problem(robot: taplan.Robot) -> tuple[CollisionWorld, np.ndarray, np.ndarray]:
    """A panel between start and goal of the right hand (the straight segment is blocked)."""
    scene = Scene()
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    scene.add("box", Box((0.12, 0.2, 0.16)), ([0.5, 0.0, -0.32], [0, 0, 0, 1]))
    return CollisionWorld(robot, scene), robot.home.copy(), _goal(robot)


def test_sampled_plan_whose_smoothing_does_not_fit_is_returned_unsmoothed(
    robot: taplan.Robot, monkeypatch: pytest.MonkeyPatch
) -> None:
    goal = _goal(robot)
    start = robot.home
    world = _plate_below(robot, goal, 0.05)
    monkeypatch.setattr(motion, "SMOOTH_MIN", 1e6)  # no budget can fit the smoothing now
    plan = plan_motion(robot, start, goal, world=world, stages=("rrt-connect",), max_time=5.0, seed=1)
    assert plan.report.stage == "rrt-connect" and not plan.report.smoothed
    assert any("unsmoothed" in note for note in plan.report.notes)
    assert _samples(world, plan.trajectory, start, 400).min() >= 0.01 / 4 - 1e-9
    np.testing.assert_allclose(plan.trajectory(plan.trajectory.duration), goal, atol=1e-9)


def test_budget_bounds_the_whole_call(robot: taplan.Robot) -> None:
    """Returns or raises within max_time + BUDGET_TOLERANCE; the extra 0.5 s covers a loaded test machine
    (the benchmark records the tolerance itself on every problem)."""
    world, start, goal = _hard_problem(robot)
    target = {"right_tcp": robot.frame_pose(goal, "right_tcp")}
    for max_time, stages in ((0.3, ("rrt-connect",)), (0.3, motion.STAGES), (1.0, ("optimization",))):
        begin = time.perf_counter()
        try:
            plan = plan_motion(robot, start, target, world=world, stages=stages, max_time=max_time)
            assert plan.report.elapsed <= time.perf_counter() - begin
        except PlanningError as exc:
            assert "budget" in str(exc) or f"within {max_time:g} s" in str(exc)
        assert time.perf_counter() - begin <= max_time + motion.BUDGET_TOLERANCE + 0.5


def test_smoothed_path_gets_no_fallback_timings(robot: taplan.Robot, monkeypatch: pytest.MonkeyPatch) -> None:
    """With a certified plan in hand, a smoothed path whose fastest timing is refused is dropped: the slower timings
    of the fallback chain (seconds under load) are not tried for it; without that option they are."""
    import dataclasses

    world = CollisionWorld(robot, Scene())
    goal = _goal(robot)
    middle = (robot.home + goal) / 2
    middle[robot.group("right").indices[1]] += 0.3
    path = [robot.home, middle, goal]
    active = np.array(robot.group("right").indices)
    real = motion.verify_trajectory
    verified: list[float] = []

    def refuse_the_first(world, trajectory, **options):  # noqa: ANN001, ANN202 (a stand-in)
        check = real(world, trajectory, **options)
        verified.append(trajectory.duration)
        if len(verified) == 1:
            return dataclasses.replace(check, collision_free=False, min_clearance=0.001, pair=("right_link6", "x"))
        return check

    monkeypatch.setattr(motion, "verify_trajectory", refuse_the_first)
    times = dict.fromkeys(("timing", "verify"), 0.0)
    args = (robot, world, path, [], active, robot.planning_limits, robot.home, goal, 0.01, 0.05)
    refused = motion._time_and_verify(*args, time.perf_counter() + 30.0, times, fallbacks=False)
    assert isinstance(refused, str) and "right_link6" in refused and len(verified) == 1
    verified.clear()
    timed = motion._time_and_verify(*args, time.perf_counter() + 30.0, times)
    assert not isinstance(timed, str) and timed.fallback.startswith("timing fell back to") and len(verified) == 2


def test_the_optimisers_qp_stops_at_the_deadline(robot: taplan.Robot, monkeypatch: pytest.MonkeyPatch) -> None:
    """daqp gets the time left as its time limit, and a QP that hits it ends the optimisation (one two-arm QP on the
    real body took 3.4 s under load); without a deadline no limit is set."""
    import qpsolvers

    from taplan.planning import optimize

    world, start, goal = _hard_problem(robot)
    active = np.array(robot.group("right").indices)
    limits = robot.planning_limits
    real = qpsolvers.solve_qp
    given: list[float | None] = []

    def timed_out(*args, **options):  # noqa: ANN002, ANN003, ANN202 (a stand-in: the solver ran out of time)
        given.append(options.get("time_limit"))
        if options.get("time_limit") is None:
            return real(*args, **options)
        time.sleep(options["time_limit"])
        return None

    monkeypatch.setattr(optimize.qpsolvers, "solve_qp", timed_out)
    path = np.array([start, goal])
    optimize.optimize_path(world, path, active, limits.lower, limits.upper, 0.01, max_iterations=1)
    assert given and given[0] is None  # no deadline, no limit (and the world's engine is built now)
    given.clear()
    begin = time.perf_counter()
    result = optimize.optimize_path(world, path, active, limits.lower, limits.upper, 0.01, deadline=begin + 1.0)
    assert result is None and len(given) == 1 and 0 < given[0] <= 1.0  # [s]: the time left, and no second QP
    assert time.perf_counter() - begin < 1.0 + 0.3


def test_large_qps_go_to_the_sparse_solver_and_agree_with_the_dense_one(
    robot: taplan.Robot, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``solver="auto"``: daqp up to ``LARGE_QP`` variables, osqp above (its sparse ADMM is several times faster on the
    smoother's two-arm QPs); with every QP forced past the threshold the optimised path keeps the margin and is as
    short as daqp's within 2 % (osqp stops at 1e-6 residuals, daqp solves exactly)."""
    import qpsolvers

    from taplan.planning import optimize

    world, start, goal = _hard_problem(robot)
    active = np.array(robot.group("right").indices)
    limits = robot.planning_limits
    real = qpsolvers.solve_qp
    used: list[tuple[str, int]] = []

    def recording(P, q, *args, solver: str, **options):  # noqa: ANN001, ANN002, ANN003, ANN202
        used.append((solver, len(q)))
        return real(P, q, *args, solver=solver, **options)

    monkeypatch.setattr(optimize.qpsolvers, "solve_qp", recording)
    path = np.array([start, goal])
    dense = optimize.optimize_path(world, path, active, limits.lower, limits.upper, 0.01)
    assert dense is not None and used and all(s == "daqp" and n <= optimize.LARGE_QP for s, n in used)
    used.clear()
    monkeypatch.setattr(optimize, "LARGE_QP", 0)
    sparse = optimize.optimize_path(world, path, active, limits.lower, limits.upper, 0.01)
    assert sparse is not None and used and all(s == "osqp" for s, _ in used)
    assert sparse.clearance >= 0.01  # [m]

    def length(p: np.ndarray) -> float:
        return float(np.linalg.norm(np.diff(p[:, active], axis=0), axis=1).sum())  # [rad]

    assert length(sparse.path) <= 1.02 * length(dense.path)


def test_an_unknown_qp_solver_is_refused_naming_the_valid_ones(robot: taplan.Robot) -> None:
    from taplan.planning import optimize_path

    world, start, goal = _hard_problem(robot)
    limits = robot.planning_limits
    active = np.array(robot.group("right").indices)
    valid = "solver: expected 'auto' or an installed qpsolvers backend .*received 'simplex'"
    with pytest.raises(InvalidInputError, match=valid):
        optimize_path(world, np.array([start, goal]), active, limits.lower, limits.upper, 0.01, solver="simplex")
