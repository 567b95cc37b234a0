"""The sampler of plan_motion in narrow places: its compiled clearance test, its certified paths, and the margin it
gives up (down to the floor, never below) when no path keeps the full margin."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import taplan
from taplan.planning import motion, plan_motion, rrt_connect
from taplan.planning.compiled_check import ClearanceCheck
from taplan.planning.motion import _margins
from taplan.planning.rrt import SPACING_SHARE, rrt_connect_groups, rrt_connect_shrinking
from taplan.planning.verify import check_segment
from taplan.scene import Box, CollisionWorld, Cylinder, HalfSpace, Scene, Sphere

ACROSS = [-0.841, -1.177, 1.323, -1.504, -0.348, -0.033, -0.58]  # the right arm reaching across the box (the
# docs' old pose [-0.694, -1.537, ...] puts the upper arm into the shoulders' body)


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _random(robot: taplan.Robot, rng: np.random.Generator) -> np.ndarray:
    limits = robot.planning_limits
    return limits.lower + rng.uniform(0, 1, robot.nq) * (limits.upper - limits.lower)


def _goal(robot: taplan.Robot) -> np.ndarray:
    q = robot.home.copy()
    q[robot.group("right").indices] = ACROSS
    return q


def _box_on_table(robot: taplan.Robot) -> CollisionWorld:
    """The straight segment home -> ACROSS passes through the box."""
    scene = Scene()
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    scene.add("box", Box((0.12, 0.2, 0.16)), ([0.5, 0.0, -0.32], [0, 0, 0, 1]))
    return CollisionWorld(robot, scene)


@pytest.mark.parametrize("clearance", [0.0, 0.005, 0.012])
def test_clearance_check_agrees_with_the_worlds_distances(robot: taplan.Robot, clearance: float) -> None:
    scene = Scene()
    scene.add("floor", HalfSpace(), ([0, 0, -0.9], [0, 0, 0, 1]))
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    scene.add("ball", Sphere(0.08), ([0.45, 0.3, -0.1], [0, 0, 0, 1]))
    scene.add("pole", Cylinder(0.01, 1.0), ([0.4, -0.3, -0.3], [0, 0, 0, 1]))
    scene.attach("cup", Cylinder(0.035, 0.12), "left_tcp", ([0, 0, 0.06], [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    check = ClearanceCheck(world, clearance)
    rng = np.random.default_rng(3)
    outcomes = []
    for _ in range(150):
        q = _random(robot, rng)
        d = world.min_distance(q)[0]
        if abs(d - clearance) > 1e-6:  # [m]: GJK on cylinders iterates to ~1e-7
            assert check(q) == (d >= clearance), (d, clearance)
            outcomes.append(d >= clearance)
    assert 0 < sum(outcomes) < len(outcomes)  # both answers were exercised
    assert check.checks == len(outcomes)


def test_clearance_check_of_the_moving_joints_tests_the_pairs_they_move(robot: taplan.Robot) -> None:
    """With the right arm's joints: every pair with a right-arm body (or what it carries) is tested, no pair of two
    bodies that stay put (the left arm against the table, the torso against the floor); the answers are those of
    the world's distances over the tested pairs."""
    scene = Scene()
    scene.add("floor", HalfSpace(), ([0, 0, -0.9], [0, 0, 0, 1]))
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    scene.attach("cup", Cylinder(0.035, 0.12), "right_tcp", ([0, 0, 0.06], [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    active = np.array(robot.group("right").indices)
    check = ClearanceCheck(world, 0.01, active)
    right = {b.name for b in world.bodies if b.group == "right"} | {"cup"}
    every = ClearanceCheck(world, 0.01).pairs
    assert set(check.pairs) == {p for p in every if set(p) & right}
    assert ("left_link4", "table") in every and ("left_link4", "table") not in check.pairs
    assert ("right_link4", "table") in check.pairs and ("left_link4", "right_link6") in check.pairs
    rng = np.random.default_rng(5)
    outcomes = []
    for _ in range(100):
        q = robot.home.copy()
        q[active] = _random(robot, rng)[active]
        d = world.distances(q, jacobian=False)
        tested = min(x for p, x in zip(d.pairs, d.distance, strict=True) if set(p) & right)
        if abs(tested - 0.01) > 1e-6:
            assert check(q) == (tested >= 0.01)
            outcomes.append(tested >= 0.01)
    assert 0 < sum(outcomes) < len(outcomes)


def test_clearance_motion_cannot_step_over_a_thin_obstacle(robot: taplan.Robot) -> None:
    """A 2 cm ball on the forearm's path: the end states are clear, the motion is refused."""
    world = CollisionWorld(robot, Scene())
    forearm = next(b for b in world.bodies if b.name == "right_link4")
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, robot.home)
    center = data.oMi[forearm.joint].act((np.asarray(forearm.start) + np.asarray(forearm.end)) / 2)
    scene = Scene()
    scene.add("ball", Sphere(0.01), (center, [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    j = robot.group("right").indices[1]
    q_a, q_b = robot.home.copy(), robot.home.copy()
    q_a[j] -= 0.3
    q_b[j] += 0.3
    margin = 0.01
    check = ClearanceCheck(world, margin)
    assert check(q_a) and check(q_b) and not check(robot.home)
    assert not check.motion(q_a, q_b, spacing=0.8 * margin)
    # the states it tested are no more than the spacing of robot-point travel apart
    travel = world.max_point_speed_bound(q_a, q_b)
    assert travel / 0.008 > 20 and check.checks <= int(np.ceil(travel / 0.008)) + 3
    # the sampler's own spacing cannot step over the 2 cm ball either (the band is 2 cm plus the margin each side)
    assert not check.motion(q_a, q_b, spacing=SPACING_SHARE * margin)


def test_sampled_path_is_certified_edge_by_edge(robot: taplan.Robot) -> None:
    world = _box_on_table(robot)
    goal = _goal(robot)
    active = np.array(robot.group("right").indices)
    limits = robot.planning_limits
    margin = 0.01
    assert not check_segment(world, robot.home, goal, margin).valid
    path = rrt_connect(
        world, robot.home, goal, active, limits.lower, limits.upper, margin, max_time=30.0, rng=np.random.default_rng(0)
    )
    assert path is not None
    np.testing.assert_allclose(path[0], robot.home, atol=0)
    np.testing.assert_allclose(path[-1], goal, atol=0)
    others = np.setdiff1d(np.arange(robot.nq), active)
    for a, b in zip(path[:-1], path[1:], strict=True):
        np.testing.assert_allclose(a[others], robot.home[others], atol=0)  # only the right arm moves
        assert check_segment(world, a, b, margin, points=margin / 2).valid
        for s in np.linspace(0, 1, 25):  # an independent sampled look at the certificate
            assert world.min_distance(a + s * (b - a))[0] >= margin / 2 - 1e-9


def test_margins_shrink_to_the_floor_and_no_further() -> None:
    assert _margins(0.01, 0.0025) == (0.01, 0.005, 0.0025)
    assert _margins(0.004, 0.0025) == (0.004, 0.0025)
    assert _margins(0.0025, 0.0025) == (0.0025,)
    assert min(_margins(0.1, 0.003)) == 0.003


def test_sampler_shrinks_its_margin_when_the_widest_is_impossible(robot: taplan.Robot) -> None:
    """At 20 cm not even the start is clear: the trees grow no further there, the search goes on at 1 cm."""
    world = _box_on_table(robot)
    goal = _goal(robot)
    active = np.array(robot.group("right").indices)
    limits = robot.planning_limits
    assert world.min_distance(robot.home)[0] < 0.2
    found = rrt_connect_shrinking(
        world, robot.home, goal, active, limits.lower, limits.upper, (0.2, 0.01), shares=(0.2,), max_time=30.0
    )
    assert found is not None
    path, kept = found
    assert kept == 0.01
    for a, b in zip(path[:-1], path[1:], strict=True):
        assert check_segment(world, a, b, kept, points=kept / 2).valid


def test_both_arms_are_moved_one_after_the_other_on_certified_edges(robot: taplan.Robot) -> None:
    """The right arm around the box, the left arm mirrored to the other side: the path first moves one arm while
    the other holds, then the other; every edge is certified at half the margin it reports."""
    world = _box_on_table(robot)
    goal = _goal(robot)
    left, right = np.array(robot.group("left").indices), np.array(robot.group("right").indices)
    goal[left] = robot.home[left] + np.array([0.3, 0.2, -0.2, 0.3, 0.0, 0.2, 0.0])
    assert world.min_distance(goal)[0] >= 0.01 and not check_segment(world, robot.home, goal, 0.01).valid
    limits = robot.planning_limits
    found = rrt_connect_groups(
        world,
        robot.home,
        goal,
        [left, right],
        limits.lower,
        limits.upper,
        (0.01, 0.005),
        shares=(0.7,),
        max_time=30.0,
        rng=np.random.default_rng(2),
    )
    assert found is not None
    path, kept = found
    assert kept in (0.01, 0.005)
    np.testing.assert_allclose(path[0], robot.home, atol=0)
    np.testing.assert_allclose(path[-1], goal, atol=0)
    # one arm moves while the other holds: each edge moves one arm only, and the arms move in two runs
    edges = list(zip(path[:-1], path[1:], strict=True))
    moved = ["left" if np.abs(b[left] - a[left]).max() > 0 else "right" for a, b in edges]
    for a, b in edges:
        assert np.abs(b[left] - a[left]).max() == 0 or np.abs(b[right] - a[right]).max() == 0
        assert check_segment(world, a, b, kept, points=kept / 2).valid
    assert sum(x != y for x, y in zip(moved[:-1], moved[1:], strict=True)) == 1


def test_plan_through_a_passage_reports_the_margin_it_kept(
    robot: taplan.Robot, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The plan keeps the sampler's margin (5 mm here, the 20 cm first try being impossible) at its waypoints and a
    quarter of it along the timed trajectory; the report and a note say so."""
    world = _box_on_table(robot)
    start, goal = robot.home, _goal(robot)
    monkeypatch.setattr(motion, "_margins", lambda margin, floor: (0.2, 0.005))
    plan = plan_motion(robot, start, goal, world=world, stages=("rrt-connect",), max_time=30.0, seed=0)
    assert plan.report.stage == "rrt-connect" and plan.report.margin == 0.005
    assert any("keeps 5.00 mm" in note for note in plan.report.notes)
    for q in plan.path:
        assert world.min_distance(q)[0] >= 0.005 - 1e-9
    index = robot.indices(plan.trajectory.joint_names)
    lowest = np.inf
    for t in np.linspace(0, plan.trajectory.duration, 300):
        q = start.copy()
        q[index] = plan.trajectory(t)
        lowest = min(lowest, world.min_distance(q)[0])
    assert lowest >= 0.005 / 4 - 1e-9
    assert plan.report.min_clearance >= 0.005 / 4 - 1e-9
