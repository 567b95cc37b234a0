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


def test_a_pose_inside_perceived_voxels_is_named(setup) -> None:
    """The same check against voxels (a grid lookup, no coal octree) names the occupancy obstacle; a target beside
    the voxels is not called inside."""
    import numpy as np

    from taplan.scene import Occupancy, Scene

    robot, _ = setup
    voxels = np.stack(np.meshgrid(np.arange(10), np.arange(10), np.arange(10), indexing="ij"), -1).reshape(-1, 3)
    scene = Scene()
    scene.add("perceived", Occupancy(0.01, [0.45, -0.1, -0.37], voxels), ([0.0, 0.0, 0.0], [0, 0, 0, 1]))
    shape = scene.obstacles["perceived"].shape
    assert shape.contains([[0.5, -0.05, -0.32]]).tolist() == [True]
    assert shape.contains([[0.56, -0.05, -0.32], [0.5, -0.05, -0.26]]).tolist() == [False, False]
    world = CollisionWorld(robot, scene)
    T = robot.frame_pose(robot.home, "right_ee")
    T[:3, 3] = [0.5, -0.05, -0.32]  # inside the voxels' cube [m]
    with pytest.raises(PlanningError, match=r"the target of right_ee is inside perceived"):
        plan_motion(robot, robot.home, {"right_ee": T}, world=world, seed=0, max_time=5.0)
