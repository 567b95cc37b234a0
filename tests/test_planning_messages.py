"""plan_motion's goal errors say why: a pose out of reach and a pose inside an obstacle are told apart."""

from __future__ import annotations

import pytest

import taplan
from taplan.errors import PlanningError
from taplan.planning import plan_motion
from taplan.scene import TELEAVATAR_SCENES, CollisionWorld, load_scene


@pytest.fixture(scope="module")
def setup():
    robot = taplan.Robot.teleavatar()
    return robot, CollisionWorld(robot, load_scene(TELEAVATAR_SCENES / "table.yaml", robot))


def test_a_pose_two_metres_away_is_out_of_reach(setup) -> None:
    robot, world = setup
    T = robot.frame_pose(robot.home, "right_ee")
    T[:3, 3] += [2.0, 0.0, 0.0]  # [m]
    with pytest.raises(PlanningError, match=r"out of reach \(no IK solution .* the closest ends \d+\.\d mm"):
        plan_motion(robot, robot.home, {"right_ee": T}, world=world, seed=0, max_time=5.0)


def test_a_pose_inside_the_box_is_named(setup) -> None:
    robot, world = setup
    T = robot.frame_pose(robot.home, "right_ee")
    T[:3, 3] = [0.5, -0.05, -0.32]  # the box's centre [m]
    with pytest.raises(PlanningError, match=r"the target of right_ee is inside box"):
        plan_motion(robot, robot.home, {"right_ee": T}, world=world, seed=0, max_time=5.0)
