"""taplan.planning: plans around a table, a box and a panel; certified clearance along the timed trajectory,
limits, errors (start/goal in collision with mm, unreachable pose, NaN), and verification that rejects collisions."""

from __future__ import annotations

import numpy as np
import pytest
from planning_helpers import blocked_problem

import taplan
from taplan.errors import CollisionError, InvalidInputError, PlanningError
from taplan.planning import check_segment, plan_motion, verify_trajectory
from taplan.scene import Box, CollisionWorld, Scene
from taplan.timing import jerk_limited, limit_usage

CLEARANCE_TOL = 1e-3  # [m] the dense independent check may see 1 mm less than the certified floor... never below 0
LIMIT_TOL = 1e-6  # relative


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _table_and_panel() -> Scene:
    scene = Scene()
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.45], [0, 0, 0, 1]))
    scene.add("panel", Box((0.5, 0.02, 0.45)), ([0.5, 0.0, -0.2], [0, 0, 0, 1]))
    return scene


def _dense_min_distance(world: CollisionWorld, trajectory: taplan.Trajectory, travel: float = 1e-3) -> float:
    """Independent check: samples so that no link point moves more than ``travel`` [m] between them."""
    t, lowest, previous = 0.0, np.inf, None
    dt = 1e-3
    while t <= trajectory.duration:
        q = trajectory(t)
        if previous is not None and world.max_point_speed_bound(previous, q) > travel:
            t -= dt / 2
            dt /= 2
            continue
        lowest = min(lowest, world.min_distance(q)[0])
        previous, t, dt = q, t + dt, dt * 1.5
    return min(lowest, world.min_distance(trajectory(trajectory.duration))[0])


def test_plan_around_obstacles_is_certified_and_within_limits(robot) -> None:
    scene = _table_and_panel()
    world = CollisionWorld(robot, scene)
    start, goal = blocked_problem(robot, world)
    plan = plan_motion(robot, start, goal, world=world, seed=1)
    report = plan.report
    assert report.success and report.stage in ("optimization", "rrt-connect")
    trajectory = plan.trajectory
    np.testing.assert_allclose(trajectory(0.0), start, atol=1e-9)
    np.testing.assert_allclose(trajectory(trajectory.duration), goal, atol=1e-9)
    assert limit_usage(trajectory, robot.planning_limits).within(LIMIT_TOL, jerk=True)
    assert report.min_clearance >= 0.01 / 4  # the certified floor [m]
    assert _dense_min_distance(world, trajectory) > 0.0  # independent: no collision anywhere [m]
    stages = {"validate", "goal_ik", "straight", "optimize", "sample", "smooth", "timing", "verify"}
    assert set(report.stage_times) == stages
    assert report.path_length >= np.linalg.norm(goal - start) - 1e-9


def test_pose_goal_reaches_the_pose_without_collision(robot) -> None:
    scene = _table_and_panel()
    world = CollisionWorld(robot, scene)
    rng = np.random.default_rng(4)
    right = robot.group("right").indices
    for _ in range(200):  # a seeded collision-free goal configuration for the right arm
        q_goal = robot.home.copy()
        q_goal[right] += rng.uniform(-0.4, 0.4, 7)
        q_goal = np.clip(q_goal, robot.planning_limits.lower, robot.planning_limits.upper)
        if world.min_distance(q_goal)[0] > 0.015:
            break
    assert world.min_distance(q_goal)[0] > 0.015
    target = robot.frame_pose(q_goal, "right_tcp")
    plan = plan_motion(robot, robot.home, {"right_tcp": target}, world=world)
    reached = robot.frame_pose(plan.trajectory(plan.trajectory.duration), "right_tcp")
    assert np.linalg.norm(reached[:3, 3] - target[:3, 3]) < 1e-3  # [m]
    assert _dense_min_distance(world, plan.trajectory) > 0.0
    left = robot.group("left").indices
    np.testing.assert_allclose(plan.trajectory(plan.trajectory.duration)[left], robot.home[left], atol=1e-12)


def test_start_and_goal_in_collision_name_the_pair_in_mm(robot) -> None:
    q = robot.home
    hand = robot.frame_pose(q, "left_ee")[:3, 3]
    scene = Scene()
    scene.add("block", Box((0.1, 0.1, 0.1)), (hand.tolist(), [0, 0, 0, 1]))
    with pytest.raises(CollisionError, match=r"start: .* collides with block \(penetration \d+\.\d mm") as info:
        plan_motion(robot, q, q + 0.1, scene)
    assert info.value.argument == "start" and info.value.pair[1] == "block"
    clear = Scene()
    clear.add("block", Box((0.1, 0.1, 0.1)), ((hand + [0.0, 0.0, 0.5]).tolist(), [0, 0, 0, 1]))
    goal = q.copy()
    with pytest.raises(CollisionError, match="goal"):
        far = Scene()
        far.add("block", Box((0.1, 0.1, 0.1)), (hand.tolist(), [0, 0, 0, 1]))
        start = q.copy()
        start[robot.group("left").indices] += [0.0, 0.0, 0.0, -0.6, 0.0, 0.0, 0.0]
        start = np.clip(start, robot.planning_limits.lower, robot.planning_limits.upper)
        if CollisionWorld(robot, far).min_distance(start)[0] < 0.015:
            pytest.skip("the moved start still touches the block")
        plan_motion(robot, start, goal, far)


def test_bad_inputs(robot) -> None:
    q = robot.home
    with pytest.raises(InvalidInputError, match="start"):
        plan_motion(robot, np.full(robot.nq, np.nan), q)
    with pytest.raises(InvalidInputError, match="goal"):
        plan_motion(robot, q, q)
    T = np.eye(4)
    T[:3, 3] = [2.0, 0.0, 0.0]  # 2 m in front: out of reach
    with pytest.raises(PlanningError, match=r"left_tcp.*out of reach \(no IK solution"):
        plan_motion(robot, q, {"left_tcp": T}, ik_seeds=1)
    with pytest.raises(InvalidInputError, match="margin"):
        plan_motion(robot, q, q + 0.05, margin=-1.0)


def test_verification_rejects_a_trajectory_through_an_obstacle(robot) -> None:
    scene = _table_and_panel()
    world = CollisionWorld(robot, scene)
    start, goal = blocked_problem(robot, world)
    straight = jerk_limited(np.array([start, goal]), robot.planning_limits).trajectory
    verdict = verify_trajectory(world, straight, floor=0.0)
    assert not verdict.collision_free
    assert verdict.min_clearance < 1e-3
    assert "panel" in verdict.pair or "table" in verdict.pair or verdict.pair[0] != ""


def test_segment_check_certifies_half_the_margin(robot) -> None:
    world = CollisionWorld(robot, _table_and_panel())
    a = robot.home.copy()
    b = a.copy()
    b[robot.group("right").indices] -= 0.3  # (+0.3 puts the right hand, now along the fingers, into the table)
    check = check_segment(world, a, b, 0.01)
    assert check.valid
    for s in np.linspace(0, 1, 101):  # the certificate holds between its evaluations too
        assert world.min_distance(a + s * (b - a))[0] >= 0.005 - CLEARANCE_TOL


def _polyline_min_distance(world: CollisionWorld, path: np.ndarray, travel: float = 1e-3) -> float:
    """Independent check of a joint-space polyline: samples at most ``travel`` [m] of link-point motion apart."""
    lowest = np.inf
    for a, b in zip(path[:-1], path[1:], strict=True):
        count = max(2, int(np.ceil(world.max_point_speed_bound(a, b) / travel)) + 1)
        for s in np.linspace(0.0, 1.0, count):
            lowest = min(lowest, world.min_distance(a + s * (b - a))[0])
    return lowest


def test_optimizer_pushes_the_straight_line_out_of_collision(robot) -> None:
    from taplan.planning.optimize import optimize_path

    world = CollisionWorld(robot, _table_and_panel())
    start, goal = blocked_problem(robot, world)
    active = robot.group("left").indices
    limits = robot.planning_limits
    straight_clearance = _polyline_min_distance(world, np.array([start, goal]), travel=5e-3)
    result = optimize_path(world, np.array([start, goal]), active, limits.lower, limits.upper, 0.01)
    assert result is not None, "the optimiser should solve this detour"
    path = result.path
    np.testing.assert_allclose(path[0], start, atol=0.0)
    np.testing.assert_allclose(path[-1], goal, atol=0.0)
    others = np.setdiff1d(np.arange(robot.nq), active)
    np.testing.assert_allclose(path[:, others], np.repeat(start[None, others], len(path), axis=0), atol=0.0)
    assert np.all(path >= limits.lower - 1e-9) and np.all(path <= limits.upper + 1e-9)
    assert straight_clearance < 0.01  # the straight segment was blocked [m]
    assert _polyline_min_distance(world, path) >= 0.01 / 2 - CLEARANCE_TOL  # certified: half the margin [m]
    assert result.clearance >= 0.01 / 2
    straight = np.linalg.norm(goal - start)
    length = np.linalg.norm(np.diff(path, axis=0), axis=1).sum()
    assert straight <= length <= 2.0 * straight  # a local detour, not a wander [rad]


def test_optimizer_as_smoother_shortens_a_detour(robot) -> None:
    from taplan.planning.optimize import optimize_path

    world = CollisionWorld(robot, Scene())
    limits = robot.planning_limits
    active = robot.group("right").indices
    start, goal, detour = robot.home.copy(), robot.home.copy(), robot.home.copy()
    goal[active] += [0.4, -0.3, 0.2, -0.5, 0.3, 0.2, 0.1]
    detour[active] += [-0.5, -0.3, 0.6, -0.1, -0.4, 0.5, 0.4]  # (-0.6 on joint 2: upper arm at the shoulders)
    goal, detour = np.clip(goal, limits.lower, limits.upper), np.clip(detour, limits.lower, limits.upper)
    seed = np.array([start, detour, goal])
    assert world.min_distance(detour)[0] > 0.01 and check_segment(world, start, detour, 0.01).valid
    result = optimize_path(world, seed, active, limits.lower, limits.upper, 0.01)
    assert result is not None
    before = np.linalg.norm(np.diff(seed, axis=0), axis=1).sum()
    after = np.linalg.norm(np.diff(result.path, axis=0), axis=1).sum()
    assert after < before - 0.5  # [rad]: pulled toward the straight line
    assert after <= np.linalg.norm(goal - start) * 1.02  # in free space: the straight line to 2 %


def test_stages_select_the_path_search_and_bad_stages_are_named(robot) -> None:
    world = CollisionWorld(robot, _table_and_panel())
    start, goal = blocked_problem(robot, world)
    sampled = plan_motion(robot, start, goal, world=world, stages=("rrt-connect",), seed=2)
    assert sampled.report.stage == "rrt-connect"
    assert sampled.report.stage_times["optimize"] == 0.0 and sampled.report.stage_times["straight"] == 0.0
    assert _dense_min_distance(world, sampled.trajectory) > 0.0
    optimized = plan_motion(robot, start, goal, world=world, stages=("straight", "optimization"), seed=2)
    assert optimized.report.stage == "optimization" and not optimized.report.smoothed
    assert _dense_min_distance(world, optimized.trajectory) > 0.0
    with pytest.raises(PlanningError, match="no collision-free path"):
        plan_motion(robot, start, goal, world=world, stages=("straight",))
    for bad in ((), ("straight", "chomp"), "straight"):
        with pytest.raises(InvalidInputError, match="stages"):
            plan_motion(robot, start, goal, world=world, stages=bad)


def test_verification_is_sound_and_tight_near_an_obstacle(robot) -> None:
    """A motion grazing a sphere: certified for a floor 3 mm under the true minimum, refused 1 mm above it."""
    from taplan.scene import Sphere
    from taplan.timing import straight_line

    right = robot.group("right").indices
    a, b = robot.home.copy(), robot.home.copy()
    b[right] += [0.5, -0.3, 0.3, -0.6, 0.2, 0.3, 0.0]
    limits = robot.planning_limits.subset([robot.joint_names[i] for i in right])
    motion = straight_line(a[right], b[right], limits)
    middle = a.copy()
    middle[right] = motion(motion.duration / 2)
    tcp = robot.frame_pose(middle, "right_tcp")[:3, 3]
    scene = Scene()
    scene.add("ball", Sphere(0.03), ((tcp + [0.0, 0.0, 0.08]).tolist(), [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    full = _full(robot, motion, a)
    truth = _dense_min_distance(world, full, travel=2e-4)  # [m]
    assert 0.005 < truth < 0.08
    certified = verify_trajectory(world, full, floor=truth - 0.003, hold=a)
    assert certified.collision_free and certified.min_clearance >= truth - 1e-9
    assert "ball" in certified.pair  # the closest approach is the grazing one
    refused = verify_trajectory(world, full, floor=truth + 0.001, hold=a)
    assert not refused.collision_free


def _full(robot: taplan.Robot, part: taplan.Trajectory, hold: np.ndarray) -> taplan.Trajectory:
    index = robot.indices(part.joint_names)
    c = part.coefficients
    coefficients = np.zeros((c.shape[0], c.shape[1], robot.nq))
    coefficients[:, 0, :] = hold
    coefficients[:, :, index] = c
    return taplan.Trajectory.from_polynomials(part.times, coefficients, robot.joint_names)
