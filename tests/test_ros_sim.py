"""The simulated robot's motion models on an in-memory transport: the joint mode follows each command within a
tick (a 50 Hz stream into its 100 Hz loop is a staircase), the interpolating model (the seed's linear branch applied
to the stream) moves along the straight line between commands at a constant speed."""

from __future__ import annotations

import numpy as np
import pytest
from sim_helpers import TICK, ready_sim

import taplan
from taplan import api
from taplan.errors import InvalidInputError
from taplan.ros.interface import FakeRosInterface
from taplan.ros.sim import SimConfig, SimulatedRobot

COMMAND = 0.02  # [s] the stream's period (50 Hz)
SPEED = 1.0  # [rad/s] of the streamed ramp on l_joint1


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _stream(fake: FakeRosInterface, sim: SimulatedRobot, commands: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 1 rad/s ramp on the left arm's first joint at 50 Hz; the sim stepped at 100 Hz. Returns (t, q, v)."""
    index = sim.indices["left"]
    start = sim.q[index].copy()
    times, positions, velocities = [], [], []
    for k in range(1, commands + 1):
        target = start.copy()
        target[0] += SPEED * COMMAND * k
        fake.deliver(api.Topics.ENABLE, {"data": 1.0})
        fake.deliver(api.Topics.joint_cmd("left"), {"name": [], "position": target.tolist()})
        for _ in range(round(COMMAND / TICK)):
            fake.advance(TICK)
            sim.step()
            times.append(fake.now())
            positions.append(sim.q[index[0]])
            velocities.append(sim.v[index[0]])
    return np.array(times), np.array(positions), np.array(velocities)


def test_interpolating_model_moves_at_the_streamed_speed(robot) -> None:
    fake, sim = ready_sim(robot, "interpolate")
    _, q, v = _stream(fake, sim, 30)
    steady = v[4:]  # after the first segment (its duration is clamped by the pause before it)
    np.testing.assert_allclose(steady, SPEED, atol=1e-6)  # [rad/s]: no staircase
    np.testing.assert_allclose(np.diff(q[4:]), SPEED * TICK, atol=1e-9)  # [rad] per tick


def test_joint_mode_turns_a_slower_stream_into_a_staircase(robot) -> None:
    fake, sim = ready_sim(robot, "joint")
    _, q, v = _stream(fake, sim, 30)
    # each 50 Hz command is reached in the first 10 ms tick, then the arm waits: 2 rad/s, 0, 2 rad/s, ...
    np.testing.assert_allclose(v[4::2], 2 * SPEED, atol=1e-6)
    np.testing.assert_allclose(v[5::2], 0.0, atol=1e-9)


def test_motion_model_is_validated(robot) -> None:
    with pytest.raises(InvalidInputError, match="config.motion"):
        SimulatedRobot(FakeRosInterface(), robot, SimConfig(motion="teleport"))
    with pytest.raises(InvalidInputError, match="config.max_segment"):
        SimulatedRobot(FakeRosInterface(), robot, SimConfig(motion="interpolate", max_segment=0.0))
