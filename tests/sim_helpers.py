"""Helpers shared by the re-planning and simulator tests: an in-memory simulator brought to READY, and a ball
obstacle (the thing that moves into a path) with its clearance."""

from __future__ import annotations

import numpy as np

import taplan
from taplan import api
from taplan.ros.interface import FakeRosInterface
from taplan.ros.sim import FsmState, SimConfig, SimulatedRobot
from taplan.scene import CollisionWorld, Scene, Sphere

TICK = 0.01  # [s] the sim's motion period (100 Hz)
BALL = 0.05  # [m] radius of the obstacle that moves into the path


def ready_sim(robot: taplan.Robot, motion: str = "joint") -> tuple[FakeRosInterface, SimulatedRobot]:
    """A simulated robot on an in-memory link, enabled (heartbeat and hold commands until READY)."""
    fake = FakeRosInterface()
    sim = SimulatedRobot(fake, robot, SimConfig(motion=motion))
    for _ in range(40):
        fake.deliver(api.Topics.ENABLE, {"data": 1.0})
        for side in api.SIDES:
            fake.deliver(api.Topics.joint_cmd(side), {"name": [], "position": sim.q[sim.indices[side]].tolist()})
        for _ in range(5):
            sim.step()
            fake.advance(TICK)
    assert sim.fsm == FsmState.READY
    return fake, sim


def with_ball(scene: Scene, centre: np.ndarray) -> Scene:
    """A copy of ``scene`` with the ball at ``centre`` [m]."""
    copy = Scene()
    for o in scene.obstacles.values():
        copy.add(o.name, o.shape, o.pose)
    copy.add("ball", Sphere(BALL), (centre.tolist(), [0, 0, 0, 1]))
    return copy


def ball_distance(world: CollisionWorld, q: np.ndarray) -> float:
    """The robot's clearance from the ball at ``q`` [m] (negative: inside)."""
    d = world.distances(q, jacobian=False)
    return min(float(x) for x, pair in zip(d.distance, d.pairs, strict=True) if "ball" in pair)
