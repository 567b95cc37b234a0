"""Everything that respects a scene respects perceived occupancy: DifferentialIK's and PoseStreamer's velocity
dampers, Cartesian lines, plan_motion and its certificate, each checked against the true primitive it was seen of.

The perceived slab is the true slab's volume sampled every 5 mm and fused at 2 cm, so its voxels cover the slab:
a clearance from the voxels is a lower bound on the clearance from the slab (the test re-checks with the slab)."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from taplan.errors import PlanningError
from taplan.ik import DifferentialIK
from taplan.planning import cartesian_offset, plan_motion
from taplan.planning.verify import verify_trajectory
from taplan.scene import Box, CollisionWorld, OccupancyGrid, Scene
from taplan.stream import PoseStreamer

MARGIN = 0.02  # [m] DifferentialIK's default collision_margin
TOL = 1e-3  # [m] linearisation of one step
SAMPLE = 0.005  # [m] spacing of the points sampled in the true slab


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _slab(centre: list[float], size: tuple[float, float, float]) -> Scene:
    scene = Scene()
    scene.add("slab", Box(size), (centre, [0, 0, 0, 1]))
    return scene


def _perceived(truth: Scene) -> Scene:
    """The true boxes' volumes as occupied voxels (an obstacle named ``perceived``)."""
    grid = OccupancyGrid(0.02)
    for obstacle in truth.obstacles.values():
        half = np.asarray(obstacle.shape.size) / 2
        axes = [np.arange(-h, h + 1e-9, SAMPLE) for h in half]
        local = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        grid.insert(local @ obstacle.pose[:3, :3].T + obstacle.pose[:3, 3])
    scene = Scene()
    scene.add("perceived", grid.snapshot())
    return scene


def _distance_to(world: CollisionWorld, q: np.ndarray, obstacle: str) -> float:
    d = world.distances(q, jacobian=False)
    return min(x for p, x in zip(d.pairs, d.distance, strict=True) if p[1] == obstacle)


@pytest.fixture(scope="module")
def table(robot) -> tuple[CollisionWorld, CollisionWorld]:
    """(perceived world, true world) of a table 30 cm below the shoulders."""
    truth = _slab([0.55, 0.0, -0.30], (0.6, 1.2, 0.04))
    return CollisionWorld(robot, _perceived(truth)), CollisionWorld(robot, truth)


def test_perceived_voxels_cover_the_true_slab(robot, table) -> None:
    seen, truth = table
    rng = np.random.default_rng(0)
    limits = robot.planning_limits
    for _ in range(30):
        q = limits.lower + rng.uniform(0.1, 0.9, robot.nq) * (limits.upper - limits.lower)
        perceived, true = _distance_to(seen, q, "perceived"), _distance_to(truth, q, "slab")
        # clear: a lower bound; in collision: in collision too (a voxel reports -radius, not the depth)
        assert perceived <= true + 1e-9 if true > 0 else perceived <= 0


def test_differential_ik_stops_at_the_margin_of_perceived_voxels(robot, table) -> None:
    seen, truth = table
    T = robot.frame_pose(robot.home, "left_ee")
    T[:3, 3] += [0.05, 0.0, -0.35]  # through the table top
    right = robot.frame_pose(robot.home, "right_ee")
    ik = DifferentialIK(robot, dt=0.01, scene=seen)
    ik.reset(robot.home)
    lowest = np.inf
    for _ in range(400):
        step = ik.step({"left_ee": T, "right_ee": right})
        lowest = min(lowest, _distance_to(seen, step.q, "perceived"))
    assert lowest >= MARGIN - TOL
    assert _distance_to(seen, step.q, "perceived") == pytest.approx(MARGIN, abs=3e-3)  # rests on the margin
    assert _distance_to(truth, step.q, "slab") >= MARGIN - TOL  # and the true table is at least as far


def test_pose_streamer_slides_along_perceived_voxels(robot, table) -> None:
    """The streamer's IK reference keeps the margin from the voxels (and so from the true table); its
    jerk-limited follower lags that reference in joint space (a finding noted in docs/perception.md)."""
    seen, truth = table
    streamer = PoseStreamer(robot, 1 / 77, frames=("left_ee",), scene=seen, timeout=None)
    streamer.reset(robot.home)
    start = robot.frame_pose(robot.home, "left_ee")
    lowest = np.inf
    for k in range(550):
        T = start.copy()
        s = min(1.0, k / 400)
        T[:3, 3] += [0.15 * s, 0.0, -0.30 * s]
        streamer.set_target({"left_ee": T})
        state = streamer.step()
        reference = streamer.ik.kin.q
        lowest = min(lowest, _distance_to(seen, reference, "perceived"))
        assert _distance_to(truth, reference, "slab") >= MARGIN - TOL
    assert lowest >= MARGIN - TOL
    assert _distance_to(truth, state.position, "slab") >= MARGIN - TOL  # at rest the command is the reference
    assert robot.frame_pose(state.position, "left_ee")[2, 3] < start[2, 3] - 0.02  # it went down [m]


def test_cartesian_lines_are_certified_against_perceived_voxels(robot) -> None:
    q = robot.home
    hand = robot.frame_pose(q, "right_ee")[:3, 3]
    truth = _slab((hand + [0.0, 0.0, -0.14]).tolist(), (0.3, 0.3, 0.02))
    seen = CollisionWorld(robot, _perceived(truth))
    free = cartesian_offset(robot, q, {"right_ee": [0.0, 0.0, 0.05]}, scene=seen, clearance=0.005)
    assert free.min_clearance > 0.005
    true_world = CollisionWorld(robot, truth)
    samples = free.trajectory(np.linspace(0.0, free.duration, 200))
    assert min(true_world.min_distance(s)[0] for s in samples) > 0.005
    with pytest.raises(PlanningError, match="perceived"):
        cartesian_offset(robot, q, {"right_ee": [0.0, 0.0, -0.08]}, scene=seen)


def _blocked_problem(robot, seen: CollisionWorld, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A free start and goal of the left arm whose joint-space straight line passes through the voxels."""
    limits = robot.planning_limits
    left = robot.group("left").indices
    for _ in range(300):
        ends = []
        for _ in range(2):
            q = robot.home.copy()
            q[left] = limits.lower[left] + rng.uniform(0.1, 0.9, 7) * (limits.upper[left] - limits.lower[left])
            ends.append(q)
        if any(seen.in_collision(q, margin=0.015) for q in ends):
            continue
        line = [ends[0] + s * (ends[1] - ends[0]) for s in np.linspace(0, 1, 40)]
        if min(_distance_to(seen, q, "perceived") for q in line) < 0.0:
            return ends[0], ends[1]
    raise AssertionError("no blocked problem found")  # pragma: no cover


def test_plan_motion_and_its_certificate_use_perceived_voxels(robot) -> None:
    truth = _slab([0.55, 0.2, -0.3], (0.2, 0.2, 0.2))
    seen = CollisionWorld(robot, _perceived(truth))
    true_world = CollisionWorld(robot, truth)
    start, goal = _blocked_problem(robot, seen, np.random.default_rng(4))
    plan = plan_motion(robot, start, goal, world=seen, seed=0)
    assert plan.report.stage != "straight"  # the voxels were in the way
    certificate = verify_trajectory(seen, plan.trajectory, 0.0)
    assert certificate.collision_free and certificate.min_clearance > 0.0
    times = np.linspace(0.0, plan.trajectory.duration, 400)
    assert min(true_world.min_distance(plan.trajectory(t))[0] for t in times) > 0.0
    # the certificate refuses a trajectory through the voxels: the plan made without the scene
    blind = plan_motion(robot, start, goal, seed=0).trajectory
    assert min(_distance_to(seen, blind(t), "perceived") for t in np.linspace(0.0, blind.duration, 100)) < 0.0
    assert not verify_trajectory(seen, blind, 0.0).collision_free
