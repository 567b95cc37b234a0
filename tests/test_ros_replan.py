"""Re-planning over real DDS: ``Runner.follow`` drives ``taplan sim`` (a subprocess on its own random loopback domain)
along a :class:`~taplan.planning.Replanner`'s trajectory while a ball moves into the path during the motion.

Checked on what was actually sent: the plan was re-planned while the arm moved, the command stream has no jerk step
(third finite differences of the commanded positions within the jerk limit, across the hand-over), every command is
clear of the ball where it ended up (coal's distances, not the planner's engine), and the simulated arm reaches the
goal.
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from sim_helpers import BALL, ball_distance, with_ball

import taplan
from taplan.planning import Replanner
from taplan.ros.dds import DdsInterface, loopback_config
from taplan.ros.runner import Runner, RunnerConfig
from taplan.scene import Box, CollisionWorld, HalfSpace, Scene, Sphere

START_TIMEOUT = 30.0  # [s] a sim subprocess imports taplan and pinocchio first
RATE = 50.0  # [Hz] commands
MARGIN = 0.01  # [m] the planner's margin: every trajectory is certified at a quarter of it
MAX_TIME = 1.0  # [s] each plan's budget
LATENCY = MAX_TIME + 0.4  # [s] hand-over after an update: the budget, its 0.2 s tolerance and room for load
SLOW = 0.02  # share of the planning velocity limits: a motion long enough for an obstacle to arrive during it
GOAL_TOL = 0.01  # [rad] the runner's goal tolerance


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


@pytest.fixture
def sim_domain(tmp_path: Path) -> Iterator[int]:
    domain = random.randint(100, 230)
    log = tmp_path / "sim.log"
    command = [sys.executable, "-m", "taplan", "sim", "--loopback", "--domain-id", str(domain), "--duration", "90"]
    with open(log, "w") as out:
        process = subprocess.Popen(
            command, stdout=out, stderr=subprocess.STDOUT, env=dict(os.environ, PYTHONUNBUFFERED="1")
        )
    try:
        end = time.monotonic() + START_TIMEOUT
        while "taplan sim: TeleAvatar" not in log.read_text():
            if process.poll() is not None or time.monotonic() > end:
                raise RuntimeError(f"taplan sim did not start: {log.read_text()}")
            time.sleep(0.05)
        yield domain
    finally:
        process.kill()
        process.wait(timeout=10)


def _scene() -> Scene:
    scene = Scene()
    scene.add("floor", HalfSpace(), ([0.0, 0.0, -1.0], [0, 0, 0, 1]))
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.45], [0, 0, 0, 1]))
    return scene


def test_replans_over_dds_around_a_ball_moving_into_the_path(robot, sim_domain) -> None:
    interface = DdsInterface(sim_domain, config=loopback_config())
    # the sim is a second process on a loaded 2-core machine: its joint states can pause for 0.2 s (the runner's
    # floor) under load; stall detection is tested elsewhere (test_ros_run), here it allows half a second
    config = RunnerConfig(rate=RATE, settle_time=2.0, state_timeout=0.5, stale_periods=50.0)
    runner = Runner(interface, robot, config=config)
    start = runner.wait_for_state()
    np.testing.assert_allclose(start, robot.home, atol=1e-9)  # the sim starts at home
    scene = _scene()
    goal = start.copy()
    right = robot.group("right").indices
    goal[right] = start[right] + np.array([-0.6, -0.3, 0.4, -0.8, 0.3, 0.2, 0.0])
    goal = np.clip(goal, robot.planning_limits.lower + 0.05, robot.planning_limits.upper - 0.05)
    base = robot.planning_limits
    limits = base.replace(velocity=base.velocity * SLOW, acceleration=base.acceleration * 0.3, jerk=base.jerk * 0.3)
    replanner = Replanner(robot, scene, start, 0.0, limits=limits, margin=MARGIN, max_time=MAX_TIME, latency=LATENCY)
    replanner.set_goal(goal)
    assert replanner.update(0.0).action == "replanned"
    first = replanner.trajectory
    assert first.duration > 5.0  # room for the ball to arrive, the latency and a stop

    # the ball arrives at 10 % of the first plan, onto where the hand will be later: clear of the goal and of every
    # configuration the arm can reach before the hand-over and its stop, hit by the first plan
    arrival = 0.1 * first.duration
    reachable = [first(t) for t in np.linspace(0.0, min(arrival + LATENCY + 1.5, first.duration), 30)]
    for fraction in np.linspace(0.6, 0.95, 36):
        ball = robot.frame_pose(first(fraction * first.duration), "right_tcp")[:3, 3]
        trial = CollisionWorld(robot, with_ball(scene, ball), engine=False)
        if ball_distance(trial, goal) > 0.025 and min(ball_distance(trial, q) for q in reachable) > 0.02:
            break
    else:
        pytest.fail("no place on the path for the ball")
    moved = CollisionWorld(robot, with_ball(scene, ball), engine=False)
    assert min(ball_distance(moved, first(t)) for t in np.linspace(0, first.duration, 200)) < 0.0  # it would hit

    pushed: list[float] = []

    def updates(t: float) -> None:  # the perception of this test: the ball appears at ``arrival``
        if not pushed and t >= arrival:
            scene.put("ball", Sphere(BALL), (ball.tolist(), [0, 0, 0, 1]))
            pushed.append(t)

    result = runner.follow(replanner, duration=60.0, updates=updates)
    interface.close()

    events = [(e.action, e.reason[:80]) for e in replanner.events]
    assert result.status == "completed", (result.reason, events)
    assert pushed, "the ball never arrived"
    replans = [e for e in replanner.events[1:] if e.action == "replanned"]
    assert replans and "the scene changed" in replans[0].reason, events
    handover = replans[0].switch
    assert pushed[0] <= replans[0].time < handover <= pushed[0] + LATENCY + 0.5  # planned in the thread, in time

    # the commands actually sent: positions at the arm rate, index k at k / RATE from the first command
    sent = result.sent
    moving = np.flatnonzero(np.abs(np.diff(sent, axis=0)).max(axis=1) > 0)
    assert len(moving) > 100
    k_handover = int(round(handover * RATE))
    speed = np.abs(sent[k_handover + 1] - sent[k_handover - 1]).max() * RATE / 2
    assert speed > 0.05, speed  # handed over while the arm moved [rad/s]
    dt = 1.0 / RATE
    third = np.abs(np.diff(sent, n=3, axis=0)) / dt**3  # a jerk step would show here, whatever else does not
    assert np.all(third <= limits.jerk * (1 + 1e-6) + 1e-6), float((third / limits.jerk).max())
    second = np.abs(np.diff(sent, n=2, axis=0)) / dt**2
    assert np.all(second <= limits.acceleration * (1 + 1e-6) + 1e-6)
    assert np.all(sent >= robot.limits.lower - 1e-9) and np.all(sent <= robot.limits.upper + 1e-9)

    # independently of the planner: every command clear of the ball where it is now (coal, per command)
    clearance = min(ball_distance(moved, q) for q in sent)
    assert clearance >= MARGIN / 4 - 1e-6, clearance
    final = result.measured[-1]
    np.testing.assert_allclose(final, goal, atol=GOAL_TOL)
