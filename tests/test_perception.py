"""Perception: occupancy from depth images and points, its distances, self-filtering, camera frames, and plans in a
perceived scene checked against the true primitives."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from taplan.errors import InvalidInputError, UnknownNameError
from taplan.scene import Box, CollisionWorld, HalfSpace, Scene
from taplan.scene.camera import (
    PinholeCamera,
    add_camera_frames,
    depth_to_metres,
    load_camera_mounts,
    look_at,
)
from taplan.scene.occupancy import Occupancy, OccupancyGrid, segment_box_distance
from taplan.scene.perception import JointHistory, Perception
from taplan.scene.raycast import depth_to_16uc1, render_depth

SMALL = PinholeCamera(160, 120, 84.25, 84.25, 80.0, 60.0)  # the wrist camera's field of view at 1/4 resolution
TINY = PinholeCamera(64, 48, 33.7, 33.7, 32.0, 24.0)


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _table_scene() -> Scene:
    scene = Scene()
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    scene.add("box", Box((0.12, 0.2, 0.16)), ([0.5, 0.1, -0.32], [0, 0, 0, 1]))
    return scene


def _point_distances(occupancy: Occupancy, points: np.ndarray) -> np.ndarray:
    """Distance [m] of each point to the nearest occupied voxel box (brute force over every voxel)."""
    lo, hi = occupancy.boxes()
    out = np.empty(len(points))
    for k, p in enumerate(points):
        out[k] = np.linalg.norm(np.maximum(np.maximum(lo - p, p - hi), 0.0), axis=1).min()
    return out


def test_segment_box_distance_is_exact_against_dense_sampling() -> None:
    rng = np.random.default_rng(3)
    n = 300
    start, end = rng.uniform(-1, 1, (n, 3)), rng.uniform(-1, 1, (n, 3))
    end[:30] = start[:30]  # points
    end[30:60, 1:] = start[30:60, 1:]  # segments along x
    centre, half = rng.uniform(-0.5, 0.5, (n, 3)), rng.uniform(0.01, 0.3, (n, 3))
    d, p, q = segment_box_distance(start, end, centre - half, centre + half)
    ts = np.linspace(0, 1, 4001)
    for i in range(n):
        points = start[i] + ts[:, None] * (end[i] - start[i])
        sampled = np.linalg.norm(points - np.clip(points, centre[i] - half[i], centre[i] + half[i]), axis=1).min()
        assert d[i] <= sampled + 1e-12  # never above any point's distance
        assert sampled - d[i] <= np.linalg.norm(end[i] - start[i]) / 4000 + 1e-12  # within the sampling step
        assert abs(np.linalg.norm(p[i] - q[i]) - d[i]) < 1e-12


def test_occupancy_capsule_distances_match_every_voxel() -> None:
    rng = np.random.default_rng(0)
    voxels = np.unique(rng.integers(0, 40, (1500, 3)), axis=0)
    occupancy = Occupancy(0.02, np.array([-0.4, -0.4, -0.4]), voxels)
    C = 40
    starts = rng.uniform(-0.5, 0.6, (C, 3))
    ends = starts + rng.normal(0, 0.15, (C, 3))
    radii = rng.uniform(0.0, 0.05, C)
    d, pa, pb, n = occupancy.capsule_distances(starts, ends, radii)
    lo, hi = occupancy.boxes()
    for c in range(C):
        gap, _, _ = segment_box_distance(
            np.repeat(starts[c : c + 1], len(lo), 0), np.repeat(ends[c : c + 1], len(lo), 0), lo, hi
        )
        assert d[c] == pytest.approx(gap.min() - radii[c], abs=1e-12)
        if d[c] > 0:
            assert np.linalg.norm(pa[c] - pb[c]) == pytest.approx(d[c], abs=1e-9)
            assert np.allclose(pa[c] - pb[c], d[c] * n[c], atol=1e-9)
    # a cutoff or a bound may only report lower bounds, exact below them
    for kwargs in ({"cutoff": 0.05}, {"bound_beyond": 0.05}):
        bounded = occupancy.capsule_distances(starts, ends, radii, **kwargs)[0]
        assert np.all(bounded <= d + 1e-12)
        assert np.all((np.abs(bounded - d) < 1e-12) | (d > 0.05))  # exact (to rounding) within the limit


def test_world_reports_one_pair_per_body_with_true_jacobians(robot: taplan.Robot) -> None:
    grid = OccupancyGrid(0.02)
    xs, ys = np.meshgrid(np.arange(0.2, 0.9, 0.01), np.arange(-0.6, 0.6, 0.01))
    grid.insert(np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, -0.42)], axis=1))
    scene = Scene()
    scene.add("seen", grid.snapshot())
    world = CollisionWorld(robot, scene)
    q = robot.home.copy()
    d = world.distances(q)
    movers = [b.name for b in world.bodies if b.joint != 0]
    assert [a for a, b in d.pairs if b == "seen"] == movers  # fixed pair list: certificates compare pairs by index
    rows = [k for k, p in enumerate(d.pairs) if p[1] == "seen"]
    rng = np.random.default_rng(1)
    for _ in range(5):
        dq = rng.normal(0, 1, robot.nq)
        dq /= np.linalg.norm(dq)
        h = 1e-6
        plus = world.distances(q + h * dq, jacobian=False).distance[rows]
        minus = world.distances(q - h * dq, jacobian=False).distance[rows]
        assert np.allclose((plus - minus) / (2 * h), d.jacobian[rows] @ dq, atol=1e-5)


def test_attached_objects_keep_a_lower_bound_against_occupancy(robot: taplan.Robot) -> None:
    grid = OccupancyGrid(0.02)
    grid.insert(np.array([[0.6, 0.45, -0.1]]))
    scene = Scene()
    scene.add("seen", grid.snapshot())
    scene.attach("cup", Box((0.05, 0.05, 0.1)), "left_tcp")
    world = CollisionWorld(robot, scene)
    d = world.distances(robot.home, jacobian=False)
    k = d.pairs.index(("cup", "seen"))
    centre = robot.frame_pose(robot.home, "left_tcp")[:3, 3]
    exact = np.linalg.norm(np.maximum(np.abs(centre - np.array([0.61, 0.45, -0.09])) - 0.01, 0.0))
    radius = Box((0.05, 0.05, 0.1)).bounding_radius()
    assert d.distance[k] == pytest.approx(exact - radius, abs=1e-9)


def test_depth_decoding_ignores_zero_nan_and_out_of_range() -> None:
    camera = PinholeCamera(4, 2, 2.0, 2.0, 2.0, 1.0)
    mm = np.array([[0, 500, 1000, 65535], [250, 10, 3000, 1200]], dtype=np.uint16)
    padded = b"".join(row.tobytes() + b"\0\0" for row in mm)  # step 10 bytes for 8 of data
    metres = depth_to_metres(padded, "16UC1", camera, min_range=0.1, max_range=2.0, step=10)
    assert np.isnan(metres[0, 0]) and np.isnan(metres[0, 3]) and np.isnan(metres[1, 1]) and np.isnan(metres[1, 2])
    assert metres[0, 1] == pytest.approx(0.5) and metres[1, 3] == pytest.approx(1.2)
    floats = np.array([[np.nan, 0.5, 0.0, 1.0], [np.inf, -1.0, 1.5, 0.3]], dtype=np.float32)
    big = depth_to_metres(floats.astype(">f4").tobytes(), "32FC1", camera, big_endian=True)
    assert np.array_equal(np.isnan(big), ~np.isfinite(floats) | (floats <= 0))
    assert np.array_equal(depth_to_16uc1(np.array([[np.nan, 0.5]])), np.array([[0, 500]], dtype=np.uint16))


def test_bad_camera_input_names_the_field(robot: taplan.Robot) -> None:
    camera = PinholeCamera(4, 2, 2.0, 2.0, 2.0, 1.0)
    with pytest.raises(InvalidInputError, match="encoding"):
        depth_to_metres(b"\0" * 24, "rgb8", camera)
    with pytest.raises(InvalidInputError, match="data"):
        depth_to_metres(b"\0" * 10, "16UC1", camera)
    with pytest.raises(InvalidInputError, match="data"):
        depth_to_metres(np.zeros((3, 4)), "32FC1", camera)
    with pytest.raises(InvalidInputError, match=r"camera_info\.k"):
        PinholeCamera.from_camera_info({"width": 4, "height": 2, "k": [np.nan, 0, 2, 0, 2, 1, 0, 0, 1]})
    with pytest.raises(InvalidInputError, match=r"camera_info\.width"):
        PinholeCamera.from_camera_info({"width": 0, "height": 2, "k": [2, 0, 2, 0, 2, 1, 0, 0, 1]})
    perception = Perception(robot)
    with pytest.raises(UnknownNameError, match="no_such_camera"):
        perception.integrate_depth(np.ones((2, 4), np.float32), camera, frame="no_such_camera", q=robot.home)
    with pytest.raises(InvalidInputError, match="stamp"):
        perception.integrate_depth(np.ones((2, 4), np.float32), camera, frame="left_depth_camera", stamp=1.0)


def test_seen_surfaces_are_covered_within_the_resolution(robot: taplan.Robot) -> None:
    scene = _table_scene()
    perception = Perception(robot)
    rng = np.random.default_rng(7)
    truth = []
    for eye, target in (([0.2, 0.3, 0.1], [0.6, 0.0, -0.4]), ([0.2, -0.3, 0.1], [0.5, 0.1, -0.4])):
        T = look_at(eye, target)
        clean = render_depth(SMALL, T, scene)
        noisy = render_depth(SMALL, T, scene, noise=0.003, missing=0.1, rng=rng)
        perception.integrate_depth(depth_to_16uc1(noisy), SMALL, T_root_camera=T, q=robot.home)
        truth.append(SMALL.points(clean) @ T[:3, :3].T + T[:3, 3])
    points = np.concatenate(truth)
    assert len(points) > 10_000
    sample = points[rng.choice(len(points), 400, replace=False)]
    occupancy = perception.occupancy()
    assert np.all(_point_distances(occupancy, sample) <= perception.grid.resolution)
    # and nothing far from a true surface: every voxel's centre within a voxel of the table or the box
    centres = occupancy.centers()
    world_free = np.min(
        [
            np.linalg.norm(np.maximum(np.abs(centres - o.pose[:3, 3]) - np.asarray(o.shape.size) / 2, 0), axis=1)
            for o in scene.obstacles.values()
        ],
        axis=0,
    )
    assert np.all(world_free <= perception.grid.resolution * 1.5)


def test_free_space_seen_later_clears_a_moved_object(robot: taplan.Robot) -> None:
    scene = _table_scene()
    perception = Perception(robot, decay=None)
    T = look_at([0.3, 0.0, 0.2], [0.5, 0.0, -0.4])
    perception.integrate_depth(render_depth(SMALL, T, scene), SMALL, T_root_camera=T, q=robot.home)

    def above_table(grid: OccupancyGrid) -> int:
        centres = grid.centers(grid.occupied_keys())
        return int(np.count_nonzero(centres[:, 2] > -0.37))

    assert above_table(perception.grid) > 50
    scene.remove("box")
    report = perception.integrate_depth(render_depth(SMALL, T, scene), SMALL, T_root_camera=T, q=robot.home)
    assert report.cleared > 50 and above_table(perception.grid) == 0


def test_decay_forgets_what_is_not_seen_again() -> None:
    grid = OccupancyGrid(0.05, decay=1.0)
    grid.insert(np.array([[0.5, 0.0, 0.0]]), stamp=0.0)
    grid.insert(np.array([[0.5, 0.5, 0.0]]), stamp=0.8)
    assert grid.expire(1.5) == 1 and len(grid) == 1
    with pytest.raises(InvalidInputError, match="decay"):
        OccupancyGrid(0.05, decay=-1.0)


def test_self_filter_leaves_nothing_on_the_arms_in_100_poses(robot: taplan.Robot) -> None:
    rng = np.random.default_rng(11)
    scene = Scene()
    scene.add("floor", HalfSpace(), ([0.0, 0.0, -0.6], [0, 0, 0, 1]))
    perception = Perception(robot, padding=0.02)
    limits = robot.planning_limits
    seen_robot = 0
    for k in range(100):
        q = limits.lower + rng.uniform(0.05, 0.95, robot.nq) * (limits.upper - limits.lower)
        frame = ("left_depth_camera", "right_depth_camera")[k % 2]
        T = perception.frame_pose(frame, q)
        starts, ends, radii = perception.robot_segments(q)
        capsules = list(zip(starts, ends, radii, strict=True))
        own = render_depth(TINY, T, None, capsules=capsules)
        seen_robot += int(np.count_nonzero(np.isfinite(own)))
        depth = render_depth(TINY, T, scene, capsules=capsules, noise=0.002, rng=rng)
        perception.grid.clear()
        perception.integrate_depth(depth, TINY, frame=frame, q=q)
        perception.update_scene()
        world = CollisionWorld(robot, perception.scene)
        d = world.distances(q, jacobian=False)
        arm = [d.distance[i] for i, (a, b) in enumerate(d.pairs) if b == "perceived"]
        assert min(arm, default=np.inf) > 0.0, k
    assert seen_robot > 1000  # the cameras do see the robot: the filter has work to do


def test_images_land_where_the_camera_was_at_capture_time(robot: taplan.Robot) -> None:
    history = JointHistory()
    q0, q1 = robot.home.copy(), robot.home.copy()
    q1[robot.group("left").indices] += 0.3
    history.add(10.0, q0)
    history.add(10.2, q1)
    assert np.allclose(history.at(10.05), 0.75 * q0 + 0.25 * q1)
    with pytest.raises(InvalidInputError, match="stamp"):
        history.at(9.0)
    perception = Perception(robot)
    perception.history = history
    depth = np.full((TINY.height, TINY.width), 0.5, np.float32)
    report = perception.integrate_depth(depth, TINY, frame="left_depth_camera", stamp=10.05)
    expected = robot.frame_pose(0.75 * q0 + 0.25 * q1, "left_depth_camera")
    assert np.allclose(report.pose, expected, atol=1e-12)
    centre = expected[:3, :3] @ np.array([0.0, 0.0, 0.5]) + expected[:3, 3]
    assert _point_distances(perception.occupancy(), centre[None])[0] == 0.0


def test_point_clouds_are_placed_by_their_frame(robot: taplan.Robot) -> None:
    perception = Perception(robot)
    local = np.array([[0.0, 0.0, 0.4], [np.nan, 0.0, 1.0]])
    report = perception.integrate_points(local, frame="right_depth_camera", q=robot.home)
    assert report.measured == 2 and report.kept == 1
    T = robot.frame_pose(robot.home, "right_depth_camera")
    assert _point_distances(perception.occupancy(), (T[:3, :3] @ local[0] + T[:3, 3])[None])[0] == 0.0
    with pytest.raises(InvalidInputError, match="points"):
        perception.integrate_points(np.zeros((3, 2)), q=robot.home)


def test_camera_mounts_from_yaml_override_the_defaults(tmp_path, robot: taplan.Robot) -> None:
    path = tmp_path / "cameras.yaml"
    path.write_text(
        "cameras:\n  left_depth_camera: {parent: Link-L7, xyz: [0.0, 0.1, 0.0], xyzw: [0, 0, 0, 1], source: test}\n"
    )
    mounts = load_camera_mounts(path)
    assert mounts["left_depth_camera"].source == "test" and "right_depth_camera" in mounts
    fresh = taplan.Robot.teleavatar()
    add_camera_frames(fresh, mounts)
    T = fresh.relative_pose(fresh.home, "left_depth_camera", "Link-L7")
    assert np.allclose(T[:3, 3], [0.0, 0.1, 0.0])
    path.write_text("cameras:\n  left_depth_camera: {parent: Link-L7, xyz: [0, 0], xyzw: [0, 0, 0, 1]}\n")
    with pytest.raises(InvalidInputError, match="left_depth_camera"):
        load_camera_mounts(path)


def test_plans_in_the_perceived_scene_are_free_against_the_true_primitives(robot: taplan.Robot) -> None:
    from benchmarks._scenes import _sample, make_scene
    from taplan.planning import plan_motion
    from taplan.scene.scan import perceive

    rng = np.random.default_rng(5)
    scene = make_scene("table_box", rng)
    perception = perceive(robot, scene, camera=SMALL, seed=5)
    assert perception.scene.obstacles["perceived"].shape.kind == "occupancy"
    seen, truth = CollisionWorld(robot, perception.scene), CollisionWorld(robot, scene)
    for _ in range(2):
        start, goal = _sample(robot, seen, ("left",), rng), _sample(robot, seen, ("left",), rng)
        assert start is not None and goal is not None
        plan = plan_motion(robot, start, goal, world=seen, seed=0)
        times = np.linspace(0, plan.trajectory.duration, 300)
        assert min(truth.min_distance(plan.trajectory(t))[0] for t in times) > 0.0


def test_merged_boxes_cover_exactly_the_voxels() -> None:
    from taplan.scene.occupancy import merge_voxels

    rng = np.random.default_rng(2)
    blob = np.unique(rng.integers(0, 12, (900, 3)), axis=0)
    slab = np.stack(np.meshgrid(np.arange(30), np.arange(40), np.arange(3), indexing="ij"), -1).reshape(-1, 3)
    for voxels in (blob, slab, np.zeros((0, 3), int)):
        lo, hi = merge_voxels(voxels)
        cells = [
            np.stack(np.meshgrid(*[np.arange(a, b) for a, b in zip(low, high, strict=True)], indexing="ij"), -1)
            for low, high in zip(lo, hi, strict=True)
        ]
        covered = np.concatenate([c.reshape(-1, 3) for c in cells] or [np.zeros((0, 3), int)])
        assert len(covered) == len(voxels)  # no overlap
        assert set(map(tuple, covered.tolist())) == set(map(tuple, voxels.tolist()))  # same space
    assert len(merge_voxels(slab)[0]) == 1  # a solid slab is one box


def test_the_batched_engine_answers_occupancy_like_the_world(robot: taplan.Robot) -> None:
    """distances_many / distance_matrix (the planner's batches) include the voxels, equal to distances(q)."""
    rng = np.random.default_rng(0)
    grid = OccupancyGrid(0.02)
    grid.insert(rng.uniform([0.2, -0.6, -0.5], [0.9, 0.6, -0.1], (3000, 3)))
    scene = Scene()
    scene.add("perceived", grid.snapshot())
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    assert world.engine() is not None
    limits = robot.planning_limits
    Q = np.array([limits.lower + rng.uniform(0.1, 0.9, robot.nq) * (limits.upper - limits.lower) for _ in range(20)])
    for cutoff in (np.inf, 0.05):
        for q, batch in zip(Q, world.distances_many(Q, cutoff=cutoff), strict=True):
            single = world.distances(q, cutoff=cutoff)
            assert single.pairs == batch.pairs
            # [m]: the engine is closed-form, a single query asks coal's GJK for boxes (converged to ~1e-6)
            np.testing.assert_allclose(batch.distance, single.distance, atol=1e-6)
            # where a capsule lies parallel to a box face the witness points are not unique: either is a valid
            # gradient (25 bodies meet that case, 9 did not)
            np.testing.assert_allclose(batch.jacobian, single.jacobian, atol=1e-3)
    matrix = world.distance_matrix(Q)
    perceived = [k for k, pair in enumerate(matrix.pairs) if pair[1] == "perceived"]
    assert len(perceived) == len(world._movers)
    for n, q in enumerate(Q):
        single = world.distances(q, jacobian=False)
        by_name = dict(zip(single.pairs, single.distance, strict=True))
        np.testing.assert_allclose(matrix.distance[n, perceived], [by_name[matrix.pairs[k]] for k in perceived])
