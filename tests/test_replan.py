"""taplan.planning.Replanner: keeps a plan that stays clear, re-plans around an obstacle that moves into the path,
hands over continuously (position, velocity, acceleration) within the limits, and drives the simulated robot to the
goal over the in-memory transport without coming closer than the certified floor to the obstacle where it was."""

from __future__ import annotations

import numpy as np
import pytest
from sim_helpers import BALL, TICK, ball_distance, ready_sim, with_ball

import taplan
from taplan import api
from taplan.errors import InvalidInputError
from taplan.planning import Replanner
from taplan.scene import Box, CollisionWorld, HalfSpace, Scene, Sphere

MARGIN = 0.01  # [m] the planner's margin: the trajectory is certified at a quarter
GOAL_TOL = 1e-6  # [rad]
LIMIT_TOL = 1e-6  # relative slack of the limit checks on sampled derivatives


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _problem(robot: taplan.Robot) -> tuple[Scene, np.ndarray, np.ndarray]:
    scene = Scene()
    scene.add("floor", HalfSpace(), ([0.0, 0.0, -1.0], [0, 0, 0, 1]))
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.45], [0, 0, 0, 1]))
    start = robot.home.copy()
    goal = start.copy()
    right = robot.group("right").indices
    goal[right] = start[right] + np.array([-0.6, -0.3, 0.4, -0.8, 0.3, 0.2, 0.0])
    goal = np.clip(goal, robot.planning_limits.lower + 0.05, robot.planning_limits.upper - 0.05)
    world = CollisionWorld(robot, scene)
    assert world.min_distance(goal)[0] > MARGIN
    return scene, start, goal


def test_an_unchanged_plan_is_kept_and_a_clear_change_does_not_replan(robot) -> None:
    scene, start, goal = _problem(robot)
    replanner = Replanner(robot, scene, start, 0.0)
    replanner.set_goal(goal)
    event = replanner.update(0.0)
    assert event is not None and event.action == "replanned"
    assert replanner.update(0.1) is None  # nothing changed
    scene.add("far", Sphere(0.05), ([-1.0, 0.0, 0.5], [0, 0, 0, 1]))  # behind the robot
    event = replanner.update(0.2)
    assert event is not None and event.action == "kept"
    np.testing.assert_allclose(replanner.state(replanner.end_time + 1.0)[0], goal, atol=GOAL_TOL)
    with pytest.raises(InvalidInputError, match="latency"):
        Replanner(robot, scene, start, latency=-1.0)


def test_replans_around_an_obstacle_moving_into_the_path_in_the_simulator(robot) -> None:
    scene, start, goal = _problem(robot)
    fake, sim = ready_sim(robot)
    np.testing.assert_allclose(sim.q, start, atol=1e-9)
    t = fake.now()
    replanner = Replanner(robot, scene, start, t, max_time=2.0)
    replanner.set_goal(goal)
    assert replanner.update(t).action == "replanned"
    first = replanner.trajectory
    # a ball is pushed at 10 % of the first plan onto where the hand will be later: clear of the goal and of the
    # robot until 35 % of the motion (room for the stop), hit by the first plan after that
    arrival = t + 0.1 * first.duration
    world = CollisionWorld(robot, scene)
    before = [first(s * first.duration) for s in np.linspace(0.0, 0.35, 8)]
    for fraction in np.linspace(0.5, 0.95, 10):
        ball = robot.frame_pose(first(fraction * first.duration), "right_tcp")[:3, 3]
        trial = CollisionWorld(robot, with_ball(scene, ball))
        if ball_distance(trial, goal) > 0.03 and min(ball_distance(trial, q) for q in before) > 0.02:
            break
    else:
        pytest.fail("no place on the path for the ball")
    commanded, times, pushed = [], [], False
    end = t + 30.0
    while t < end:
        if not pushed and t >= arrival:
            scene.put("ball", Sphere(BALL), (ball.tolist(), [0, 0, 0, 1]))  # out of nowhere, onto the path
            pushed = True
        replanner.update(t)
        q, v, a = replanner.state(t)
        commanded.append((q, v, a))
        times.append(t)
        fake.deliver(api.Topics.ENABLE, {"data": 1.0})
        for side in api.SIDES:
            fake.deliver(api.Topics.joint_cmd(side), {"name": [], "position": q[sim.indices[side]].tolist()})
        fake.advance(TICK)
        sim.step()
        t = fake.now()
        if pushed and t > replanner.end_time + 0.1:
            break
    actions = [e.action for e in replanner.events]
    assert "replanned" in actions[1:], [(e.action, e.reason) for e in replanner.events]
    replan = next(e for e in replanner.events[1:] if e.action == "replanned")
    assert "the scene changed" in replan.reason
    assert np.abs(commanded[times.index(replan.time)][1]).max() > 0.1  # handed over while moving [rad/s]
    np.testing.assert_allclose(sim.q, goal, atol=1e-3)  # the sim followed to the goal
    np.testing.assert_allclose(commanded[-1][0], goal, atol=GOAL_TOL)
    q_all = np.array([c[0] for c in commanded])
    v_all = np.array([c[1] for c in commanded])
    a_all = np.array([c[2] for c in commanded])
    limits = robot.planning_limits
    assert np.all(np.abs(v_all) <= limits.velocity * (1 + LIMIT_TOL))
    assert np.all(np.abs(a_all) <= limits.acceleration * (1 + LIMIT_TOL))
    # no velocity or acceleration step at the hand-over: consecutive commands differ by at most a tick's worth
    assert np.all(np.abs(np.diff(v_all, axis=0)) <= limits.acceleration * TICK * (1 + 1e-3) + 1e-9)
    assert np.all(np.abs(np.diff(a_all, axis=0)) <= limits.jerk * TICK * (1 + 1e-3) + 1e-9)
    # after the ball arrived, every commanded configuration keeps the certified quarter margin from it
    after = np.array(times) >= arrival
    clearance = min(ball_distance(world, q) for q in q_all[after])
    assert clearance >= MARGIN / 4 - 1e-9
    # without re-planning, the first plan would have hit the ball
    assert min(ball_distance(world, first(s)) for s in np.linspace(0, first.duration, 200)) < 0.0


def test_a_plan_ready_after_its_hand_over_was_read_is_not_used(robot) -> None:
    """A control loop on another thread read states past the hand-over while the plan was computed: the update is
    "late", the replanner brakes from the latest state read (no state already read changes) and the next update
    plans from the stop; the states read stay continuous."""
    scene, start, goal = _problem(robot)
    base = robot.planning_limits
    limits = base.replace(velocity=base.velocity * 0.1)
    replanner = Replanner(robot, scene, start, 0.0, limits=limits, latency=0.2, max_time=2.0)
    replanner.set_goal(goal)
    assert replanner.update(0.0).action == "replanned"
    first = replanner.trajectory
    read = 0.25 * first.duration  # the loop is already here
    before = replanner.state(read)
    passed = [first(s * first.duration) for s in np.linspace(0.0, 0.4, 8)]
    for fraction in np.linspace(0.6, 0.95, 8):
        ball = robot.frame_pose(first(fraction * first.duration), "right_tcp")[:3, 3]
        trial = CollisionWorld(robot, with_ball(scene, ball))
        if ball_distance(trial, goal) > 0.03 and min(ball_distance(trial, q) for q in passed) > 0.02:
            break
    else:
        pytest.fail("no place on the path for the ball")
    scene.put("ball", Sphere(BALL), (ball.tolist(), [0, 0, 0, 1]))
    event = replanner.update(0.1)  # the update's time: the hand-over at 0.3 s was read long ago
    assert event.action == "late" and "past its hand-over" in event.reason, event.reason
    for x, y in zip(before, replanner.state(read), strict=True):  # the state read last stays as it was
        np.testing.assert_allclose(x, y, atol=1e-9)
    assert np.abs(before[1]).max() > 0.05  # braking from a moving state [rad/s]
    event = replanner.update(read + 0.01)
    assert event.action == "replanned", event.reason
    times = np.arange(read, replanner.end_time + 0.1, 0.01)
    states = [replanner.state(t) for t in times]
    v = np.array([s[1] for s in states])
    a = np.array([s[2] for s in states])
    assert np.all(np.abs(np.diff(v, axis=0)) <= limits.acceleration * 0.01 * (1 + 1e-3) + 1e-9)
    assert np.all(np.abs(np.diff(a, axis=0)) <= limits.jerk * 0.01 * (1 + 1e-3) + 1e-9)
    np.testing.assert_allclose(states[-1][0], goal, atol=GOAL_TOL)
    world = CollisionWorld(robot, scene, engine=False)
    assert min(ball_distance(world, s[0]) for s in states[::5]) >= MARGIN / 4 - 1e-6
