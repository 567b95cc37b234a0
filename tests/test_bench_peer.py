"""The fair OMPL peer of benchmarks/bench_planning.py: its compiled validity check sees the same bodies and pairs
as taplan's CollisionWorld, and its motion-check resolution cannot step through the thinnest obstacle."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from benchmarks._peer import THINNEST, CompiledScene, dense_check, motion_resolution
from benchmarks._scenes import make_scene
from benchmarks.bench_planning import ompl_setup
from taplan.scene import Box, CollisionWorld, Cylinder, HalfSpace, Scene, Sphere


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _random(robot: taplan.Robot, rng: np.random.Generator) -> np.ndarray:
    limits = robot.planning_limits
    return limits.lower + rng.uniform(0, 1, robot.nq) * (limits.upper - limits.lower)


def test_compiled_distances_equal_the_worlds(robot: taplan.Robot) -> None:
    scene = Scene()
    scene.add("floor", HalfSpace(), ([0, 0, -0.9], [0, 0, 0, 1]))
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    scene.add("ball", Sphere(0.08), ([0.45, 0.3, -0.1], [0, 0, 0, 1]))
    scene.add("pole", Cylinder(0.01, 1.0), ([0.4, -0.3, -0.3], [0, 0, 0, 1]))
    scene.attach("cup", Cylinder(0.035, 0.12), "left_tcp", ([0, 0, 0.06], [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    compiled = CompiledScene(world)
    assert set(compiled.pairs) == set(world.distances(robot.home, jacobian=False).pairs)
    rng = np.random.default_rng(4)
    colliding = 0
    for _ in range(60):
        q = _random(robot, rng)
        d = world.min_distance(q)[0]
        assert compiled.min_distance(q) == pytest.approx(d, abs=1e-6)  # [m]: GJK on cylinders iterates to ~1e-7
        if abs(d) > 1e-6:
            assert compiled.valid(q) == (d > 0)
        colliding += d < 0
    assert 0 < colliding < 60  # both outcomes were exercised


def test_peer_and_dense_check_see_every_capsule_of_the_real_body(robot: taplan.Robot) -> None:
    """The peer's validity check and the dense check hold the world's bodies as they are: every capsule of the
    real body (links, grippers, wrist cameras, fingers), placed where the world places them."""
    world = CollisionWorld(robot, make_scene("window", np.random.default_rng(0)))
    compiled = CompiledScene(world)
    names = [g.name for g in compiled.geometry.geometryObjects]
    assert set(names) == {b.name for b in world.bodies} | set(world.scene.obstacles)
    for arm in ("left", "right"):
        for part in ("fingers_0", "fingers_1", "gripper_0", "wrist_camera", "link6"):
            assert f"{arm}_{part}" in names
    fingers = [p for p in compiled.pairs if "right_fingers_0" in p]
    assert any(o in p for p in fingers for o in world.scene.obstacles)  # fingers against the scene are checked
    # a sphere at the fingers' capsule touches them in both checks: the compiled body is where the world's is
    body = next(b for b in world.bodies if b.name == "right_fingers_0")
    import pinocchio as pin

    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, robot.home)
    tip = data.oMi[body.joint].act(np.asarray(body.end, float))
    scene = Scene()
    scene.add("ball", Sphere(0.005), (tip, [0, 0, 0, 1]))
    at_tip = CollisionWorld(robot, scene)
    assert not CompiledScene(at_tip).valid(robot.home)
    assert at_tip.min_distance(robot.home)[0] < 0


def test_motion_resolution_moves_no_point_more_than_half_the_thinnest_obstacle(robot: taplan.Robot) -> None:
    world = CollisionWorld(robot, make_scene("window", np.random.default_rng(0)))
    active = robot.group("right").indices
    extent = 12.0  # [rad] any space extent: the resolution is a fraction of it
    step = motion_resolution(world, active, extent) * extent
    rng = np.random.default_rng(1)
    for _ in range(200):
        q = _random(robot, rng)
        direction = np.zeros(robot.nq)
        direction[active] = rng.normal(size=active.size)
        q_next = q + direction / np.linalg.norm(direction) * step
        assert world.max_point_speed_bound(q, q_next) <= THINNEST / 2 + 1e-12


def test_ompl_motion_check_does_not_step_through_a_thin_obstacle(robot: taplan.Robot) -> None:
    pytest.importorskip("ompl")
    active = robot.group("right").indices
    q_mid = robot.home.copy()
    # a 2 cm ball in the middle of the right forearm at home; the motion sweeps the forearm across it
    world = CollisionWorld(robot, Scene())
    forearm = next(b for b in world.bodies if b.name == "right_link4")
    robot_data = robot.model.createData()
    import pinocchio as pin

    pin.forwardKinematics(robot.model, robot_data, q_mid)
    placement = robot_data.oMi[forearm.joint]
    center = placement.act((np.asarray(forearm.start) + np.asarray(forearm.end)) / 2)
    scene = Scene()
    scene.add("ball", Sphere(THINNEST / 2), (center, [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    compiled = CompiledScene(world)
    assert not compiled.valid(q_mid)
    q_a, q_b = q_mid.copy(), q_mid.copy()
    q_a[active[1]] -= 0.3  # the shoulder's second joint swings the forearm 10+ cm clear on both sides
    q_b[active[1]] += 0.3
    assert compiled.valid(q_a) and compiled.valid(q_b)

    setup = ompl_setup(world, compiled, robot, q_mid, active)
    setup.setup()
    si, space = setup.getSpaceInformation(), setup.getStateSpace()
    a, b = space.allocState(), space.allocState()
    for k, j in enumerate(active):
        a[k], b[k] = float(q_a[j]), float(q_b[j])
    assert not si.checkMotion(a, b)


def test_dense_check_counts_the_collisions_of_a_motion_through_an_obstacle(robot: taplan.Robot) -> None:
    scene = Scene()
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    compiled = CompiledScene(world)
    goal = robot.home.copy()
    goal[robot.group("right").indices] = [-0.694, -1.537, 1.399, -1.306, -0.263, -0.369, -0.403]
    index = np.arange(robot.nq)

    def through(t: float) -> np.ndarray:  # home -> 30 cm below the table's top along the straight segment
        return robot.home + (goal - robot.home) * t

    collisions, lowest = dense_check(compiled, world, through, 1.0, robot.home, index)
    samples = [world.min_distance(through(t))[0] for t in np.linspace(0, 1, 200)]
    assert lowest == pytest.approx(min(lowest, min(samples)), abs=1e-3)
    assert (collisions > 0) == (min(samples) < 0)


def test_solvable_means_a_certified_path_by_either_planner_and_the_bodies_are_named(robot: taplan.Robot) -> None:
    from benchmarks.bench_planning import _solvable, markdown

    def record(success: bool, certified: bool) -> dict:
        times = dict.fromkeys(("validate", "goal_ik", "straight", "optimize", "sample", "smooth", "timing", "verify"))
        return {
            "success": success,
            "certified": certified,
            "seconds": 1.0,
            "reason": "no collision-free path found within 5 s",
            "collisions": 0 if certified else 3,
            "clearance": 0.004 if certified else -0.002,
            "path_length": 2.0,
            "duration": 1.5,
            "stage": "rrt-connect",
            "stage_times": {k: 0.1 for k in times},
        }

    rows = [  # taplan failed and OMPL certified; OMPL's path collided and taplan failed; both certified
        {"family": "window", "index": 0, "taplan": record(False, False), "ompl": record(True, True)},
        {"family": "window", "index": 1, "taplan": record(False, False), "ompl": record(True, False)},
        {"family": "window", "index": 2, "taplan": record(True, True), "ompl": record(True, True)},
    ]
    assert [_solvable(r) for r in rows] == [True, False, True]
    bodies = [b.name for b in CollisionWorld(robot, None).bodies]
    results = {"rows": rows, "seed": 0, "max_time": 5.0, "tolerance": 0.2, "travel": 1e-3, "bodies": bodies}
    text = markdown(results)
    line = next(x for x in text.splitlines() if x.startswith("| window | taplan"))
    assert "| 1/2 |" in line  # solved of solvable: the problem no planner certified does not count
    assert "right_fingers_1" in text and f"the {len(bodies)} capsules" in text
