"""DifferentialIK and PoseStreamer with a scene: targets inside an obstacle end at the margin, never inside."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from taplan.ik import DifferentialIK
from taplan.scene import Box, CollisionWorld, Scene
from taplan.stream import PoseStreamer

MARGIN = 0.02  # [m] DifferentialIK's default collision_margin
TOL = 1e-3  # [m] linearisation of one step
# [m] the streamer's jerk-limited follower lags the IK reference (up to 0.05 rad when the damper turns the hand along
# the table top) and cuts the corner between its samples: the streamed positions may dip this far below the IK's margin
FOLLOW_TOL = 0.01


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


@pytest.fixture(scope="module")
def world(robot) -> CollisionWorld:
    scene = Scene()
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.30], [0, 0, 0, 1]))
    return CollisionWorld(robot, scene)


def _table_distance(world: CollisionWorld, q: np.ndarray) -> float:
    d = world.distances(q, jacobian=False)
    return min(x for p, x in zip(d.pairs, d.distance, strict=True) if p[1] == "table")


def test_target_below_the_table_ends_at_the_margin(robot, world) -> None:
    T = robot.frame_pose(robot.home, "left_ee")
    T[:3, 3] += [0.05, 0.0, -0.35]  # 35 cm down: through the table top
    right = robot.frame_pose(robot.home, "right_ee")
    free = DifferentialIK(robot, dt=0.01)
    free.reset(robot.home)
    for _ in range(400):
        q_free = free.step({"left_ee": T, "right_ee": right}).q
    assert _table_distance(world, q_free) < -0.05  # without the scene the arm goes through [m]

    ik = DifferentialIK(robot, dt=0.01, scene=world)
    ik.reset(robot.home)
    lowest = np.inf
    for _ in range(1200):  # the hand, fingers along the table top, slides to rest there (slower than in 4 s)
        step = ik.step({"left_ee": T, "right_ee": right})
        lowest = min(lowest, _table_distance(world, step.q))
    assert lowest >= MARGIN - TOL
    assert _table_distance(world, step.q) == pytest.approx(MARGIN, abs=2e-3)  # closest safe configuration
    assert np.abs(step.velocity).max() < 1e-3  # at rest there [rad/s]


def test_streamed_poses_slide_along_the_table(robot, world) -> None:
    dt = 1 / 77
    streamer = PoseStreamer(robot, dt, frames=("left_ee",), scene=world, timeout=None)
    streamer.reset(robot.home)
    start = robot.frame_pose(robot.home, "left_ee")
    lowest = np.inf
    for k in range(900):  # over 8 s the target sweeps 15 cm forward and dives 30 cm below the table top
        T = start.copy()
        s = min(1.0, k / 600)
        T[:3, 3] += [0.15 * s, 0.0, -0.30 * s]
        streamer.set_target({"left_ee": T})
        state = streamer.step()
        lowest = min(lowest, _table_distance(world, state.position))
    assert lowest >= MARGIN - FOLLOW_TOL
    assert _table_distance(world, state.position) == pytest.approx(MARGIN, abs=2e-3)  # resting on the margin
    hand = robot.frame_pose(state.position, "left_ee")[:3, 3]
    assert hand[2] < start[2, 3] - 0.03  # it went down as far as the table allows [m]


def test_scene_limit_rejects_bad_options(robot, world) -> None:
    from taplan.errors import InvalidInputError
    from taplan.ik.limits import SceneLimit

    with pytest.raises(InvalidInputError, match="influence"):
        SceneLimit(world, margin=0.1, influence=0.05)
