"""Look where you go (:func:`taplan.planning.plan_seen`): a board in the one part of the workspace no image has
seen, an arm motion whose straight path goes through the board; the loop looks at what the motion sweeps, sees the
board and plans around it (checked against the true board with coal, independently of the voxels); a goal in unseen
space is looked at before any plan; views that see nothing new end in an error naming the unseen space."""

from __future__ import annotations

import coal
import numpy as np
import pytest
from board_helpers import BOARD_CENTRE, BOARD_SIZE, SMALL, WORKSPACE, board_scene

import taplan
from taplan.errors import InvalidInputError, UnseenSpaceError
from taplan.planning import plan_seen
from taplan.planning.seen import _swept_unknown
from taplan.planning.verify import check_segment
from taplan.scene import Box, CollisionWorld, Perception, Scene
from taplan.scene.camera import PinholeCamera
from taplan.scene.scan import RenderedViews


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


UNSEEN = ((0.45, -0.3, -0.4), (0.85, 0.3, -0.3))  # [m] the box around the board no image has seen yet


def _seen_but_the_board(robot: taplan.Robot, unknown: str = "occluded") -> Perception:
    """A map whose workspace is known free except a box around the board (unseen: counted as an obstacle); the
    board itself has not been seen."""
    perception = Perception(robot, resolution=0.01, workspace=WORKSPACE, unknown=unknown)
    h = perception.grid.resolution
    lo, hi = np.asarray(WORKSPACE[0]), np.asarray(WORKSPACE[1])
    axes = [np.arange(a + h / 2, b, h) for a, b in zip(lo, hi, strict=True)]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    inside = np.all((centres >= UNSEEN[0]) & (centres <= UNSEEN[1]), axis=1)
    keys, _ = perception.grid.keys(centres[~inside])
    perception.grid.mark_free(keys)
    perception.update_scene()
    return perception


def _through_the_board(robot: taplan.Robot) -> list[np.ndarray]:
    """A seeded left-arm motion whose straight segment goes through the true board, with ends clear of it and of
    the unseen box."""
    truth = CollisionWorld(robot, board_scene())
    unseen = CollisionWorld(robot, _seen_but_the_board(robot).scene)
    rng = np.random.default_rng(11)
    limits = robot.planning_limits
    idx = robot.group("left").indices
    for _ in range(500):
        q = [robot.home.copy(), robot.home.copy()]
        for k in range(2):
            q[k][idx] = limits.lower[idx] + rng.uniform(0.05, 0.95, len(idx)) * (limits.upper[idx] - limits.lower[idx])
        if min(min(truth.min_distance(c)[0], unseen.min_distance(c)[0]) for c in q) < 0.03:
            continue
        if not check_segment(truth, q[0], q[1], 0.0).valid:
            return q
    raise AssertionError("no seeded motion through the board")


def _true_clearance(perception: Perception, trajectory: taplan.Trajectory) -> float:
    """The smallest distance [m] between the robot's capsules along ``trajectory`` (dense) and the TRUE board,
    computed with coal alone (not with taplan's collision world or the voxels)."""
    board = coal.Box(*BOARD_SIZE)
    board_pose = coal.Transform3s(np.eye(3), BOARD_CENTRE)
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    best = np.inf
    for t in np.linspace(0.0, trajectory.duration, 300):
        starts, ends, radii = perception.robot_segments(trajectory(t))
        for a, b, r in zip(starts, ends, radii, strict=True):
            axis = b - a
            length = float(np.linalg.norm(axis))
            z = axis / length if length > 1e-9 else np.array([0.0, 0.0, 1.0])
            x = np.cross([1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0], z)
            x /= np.linalg.norm(x)
            R = np.column_stack([x, np.cross(z, x), z])
            result.clear()
            d = coal.distance(
                board, board_pose, coal.Capsule(r, length), coal.Transform3s(R, (a + b) / 2), request, result
            )
            best = min(best, d)
    return float(best)


def test_the_loop_looks_at_the_unseen_board_and_plans_around_it(robot: taplan.Robot) -> None:
    start, goal = _through_the_board(robot)
    perception = _seen_but_the_board(robot)
    half = np.asarray(BOARD_SIZE) / 2 - 0.001
    board = np.stack(np.meshgrid(*[np.linspace(-h, h, 15) for h in half], indexing="ij"), -1).reshape(-1, 3)
    board_voxels, inside = perception.grid.keys(board + BOARD_CENTRE)
    assert inside.all() and not perception.grid.occupied[board_voxels].any()  # the board is not seen
    capture = RenderedViews(perception, board_scene(), camera=SMALL, seed=0)
    seen = plan_seen(robot, perception, start, goal, capture, camera=SMALL, max_time=20.0, seed=0)
    assert seen.rounds and seen.rounds[0].views and capture.count == len(seen.views) > 0
    assert perception.grid.occupied[board_voxels].any()  # a view saw the board
    trajectory = seen.plan.trajectory
    assert np.allclose(trajectory(0.0), start, atol=1e-6) and np.allclose(
        trajectory(trajectory.duration), goal, atol=1e-6
    )
    assert _true_clearance(perception, trajectory) > 0.0
    # the plan stays where the images saw free space: nothing counted unknown within its bodies
    assert not len(_swept_unknown(perception, trajectory(np.linspace(0.0, trajectory.duration, 100)), 0.0))
    assert seen.total_time >= seen.plan_time > 0.0


def _goal_in_unseen(robot: taplan.Robot, perception: Perception) -> np.ndarray:
    """A seeded left-arm configuration clear of the true board whose gripper reaches 1 cm into counted unknown
    space."""
    truth = CollisionWorld(robot, board_scene())
    unseen = CollisionWorld(robot, perception.scene)
    rng = np.random.default_rng(5)
    limits = robot.planning_limits
    idx = robot.group("left").indices
    for _ in range(500):
        q = robot.home.copy()
        q[idx] = limits.lower[idx] + rng.uniform(0.05, 0.95, len(idx)) * (limits.upper[idx] - limits.lower[idx])
        if truth.min_distance(q)[0] >= 0.03 and unseen.min_distance(q)[0] < -0.01:
            return q
    raise AssertionError("no seeded goal in unseen space")


def test_a_goal_in_unseen_space_is_looked_at_before_planning(robot: taplan.Robot) -> None:
    perception = _seen_but_the_board(robot)
    start, goal = robot.home, _goal_in_unseen(robot, perception)
    unseen = _swept_unknown(perception, goal[None, :], 0.02)
    capture = RenderedViews(perception, board_scene(), camera=SMALL, seed=1)
    seen = plan_seen(robot, perception, start, goal, capture, camera=SMALL, max_time=20.0, seed=1)
    first = seen.rounds[0]
    assert first.plan_time == 0.0 and first.views  # views before any plan
    assert first.resolved > 0 and first.unseen == len(unseen)
    assert np.allclose(seen.plan.trajectory(seen.plan.trajectory.duration), goal, atol=1e-6)
    assert _true_clearance(perception, seen.plan.trajectory) > 0.0
    counted = np.zeros(perception.grid.occupied.shape, dtype=bool)
    counted[perception.grid.unknown_keys("occluded")] = True
    assert counted[unseen].sum() < len(unseen)  # images saw into the goal's space


def test_views_the_capture_could_not_take_are_retried_with_fresh_candidates(robot: taplan.Robot) -> None:
    """The first round's views cannot be taken (the capture returns None, e.g. no motion to them): the loop does
    not give up, the next round chooses among fresh candidates, sees the goal's space and plans."""
    perception = _seen_but_the_board(robot)
    start, goal = robot.home, _goal_in_unseen(robot, perception)
    render = RenderedViews(perception, board_scene(), camera=SMALL, seed=1)
    refused: list[str] = []

    def capture(frame: str, q: np.ndarray) -> tuple[np.ndarray, PinholeCamera] | None:
        if not refused:
            refused.append(frame)
            return None
        return render(frame, q)

    seen = plan_seen(robot, perception, start, goal, capture, camera=SMALL, views_per_round=1, max_time=20.0, seed=1)
    assert refused and seen.rounds[0].views == () and seen.rounds[0].resolved == 0
    assert any(r.views and r.resolved > 0 for r in seen.rounds[1:])
    assert np.allclose(seen.plan.trajectory(seen.plan.trajectory.duration), goal, atol=1e-6)
    assert _true_clearance(perception, seen.plan.trajectory) > 0.0


def _slot_around_the_hand(robot: taplan.Robot) -> tuple[Perception, np.ndarray, np.ndarray]:
    """A map whose workspace is seen free but for two flat plates of voxels just above and just below the left
    hand at home (8.7 mm and 11 mm from it: a slot narrower than twice the 1 cm margin, as depth noise and voxels
    that overstate a surface make them), and a goal that slides the hand out of the slot."""
    perception = Perception(robot, resolution=0.004, bounds=((0.2, -0.55, -0.7), (1.1, 0.55, 0.0)), workspace=WORKSPACE)
    grid = perception.grid
    grid.free[grid._region_keys] = True  # every workspace voxel seen free
    starts, ends, radii = perception.robot_segments(robot.home)
    hand = np.array([b.joint == robot.group("left").indices[-1] + 1 for b in perception.bodies])
    assert hand.sum() >= 3
    centre = (starts[hand] + ends[hand]).mean(axis=0) / 2
    top = max(max(starts[k, 2], ends[k, 2]) + radii[k] for k in np.flatnonzero(hand))
    bottom = min(min(starts[k, 2], ends[k, 2]) - radii[k] for k in np.flatnonzero(hand))
    h = grid.resolution
    side = np.arange(-0.08, 0.08, h / 2)
    xy = np.stack(np.meshgrid(side, side, indexing="ij"), -1).reshape(-1, 2) + centre[:2]
    for z in (top + 0.006 + h, bottom - 0.007 - h):
        plate = np.column_stack([xy, np.full(len(xy), z)])
        # not around the forearm and wrist: the plates face the hand only
        far = np.ones(len(plate), dtype=bool)
        for k in np.flatnonzero(~hand):
            u = ends[k] - starts[k]
            t = np.clip((plate - starts[k]) @ u / max(float(u @ u), 1e-12), 0.0, 1.0)
            far &= np.linalg.norm(plate - (starts[k] + t[:, None] * u), axis=1) - radii[k] > 0.03
        grid.insert(plate[far])
    perception.update_scene()
    idx = robot.group("left").indices
    goal = robot.home.copy()
    goal[idx[1]] -= 0.4  # the hand slides sideways out of the slot (the shoulder keeps its height)
    goal[idx[0]] -= 0.4 * 0.143
    return perception, robot.home.copy(), goal


def test_a_start_in_a_slot_of_seen_voxels_keeps_what_a_bent_end_keeps(robot: taplan.Robot) -> None:
    """The robot stands in a slot of seen voxels narrower than twice the margin: plan_motion refuses (no short
    segment leads to margin clearance); plan_seen plans with the clearance a bent end keeps, floor + (d - floor) / 2
    for the start's d, certifies it, and never comes closer to the voxels than a quarter of it."""
    from taplan.errors import PlanningError
    from taplan.planning import plan_motion
    from taplan.planning.ends import DEFAULT_FLOOR

    perception, start, goal = _slot_around_the_hand(robot)
    world = CollisionWorld(robot, perception.scene)
    d = world.min_distance(start)[0]
    assert DEFAULT_FLOOR < d < 0.01  # inside the 1 cm margin, clear of the floor
    with pytest.raises(PlanningError, match="no short certified segment"):
        plan_motion(robot, start, goal, world=world, max_time=5.0)

    def capture(frame: str, q: np.ndarray) -> None:
        raise AssertionError("nothing is unseen: no view is needed")

    seen = plan_seen(robot, perception, start, goal, capture, max_time=10.0)
    assert seen.margin == pytest.approx(DEFAULT_FLOOR + (d - DEFAULT_FLOOR) / 2, abs=1e-9) and seen.margin < d
    trajectory = seen.plan.trajectory
    assert np.allclose(trajectory(0.0), start, atol=1e-6)
    assert np.allclose(trajectory(trajectory.duration), goal, atol=1e-6)
    assert seen.clearance >= seen.margin / 4
    dense = [world.min_distance(trajectory(t))[0] for t in np.linspace(0.0, trajectory.duration, 200)]
    assert min(dense) >= seen.margin / 4 - 1e-9


def test_views_that_see_nothing_new_end_in_an_error_naming_the_unseen_space(robot: taplan.Robot) -> None:
    # all unseen space counts (with "occluded", what the robot's own bodies hide in an image counts as viewed)
    perception = _seen_but_the_board(robot, "occupied")
    start, goal = robot.home, _goal_in_unseen(robot, perception)

    def covered(frame: str, q: np.ndarray) -> tuple[np.ndarray, PinholeCamera]:
        # a covered lens: a surface 6 cm in front of the camera everywhere, all behind it hidden (an image of NaN,
        # no return at all, would say "nothing there": that is what a depth camera reports for empty space)
        return np.full((SMALL.height, SMALL.width), 0.06, dtype=np.float32), SMALL

    with pytest.raises(UnseenSpaceError, match=r"voxels \(1 cm\) in x, y, z = \[") as info:
        plan_seen(robot, perception, start, goal, covered, camera=SMALL, rounds=2, max_time=5.0)
    assert "no view has seen free" in str(info.value)
    centres = np.asarray(info.value.unseen)
    assert centres.ndim == 2 and centres.shape[1] == 3 and len(centres) > 0
    lo, hi = np.asarray(WORKSPACE[0]), np.asarray(WORKSPACE[1])
    assert np.all((centres >= lo) & (centres <= hi))  # unseen space is workspace space


def test_plan_seen_checks_its_arguments(robot: taplan.Robot) -> None:
    start, goal = robot.home, robot.home + 0.1
    loose = Perception(robot, resolution=0.05, unknown="free")
    with pytest.raises(InvalidInputError, match="perception"):
        plan_seen(robot, loose, start, goal, lambda f, q: None)
    perception = Perception(robot, resolution=0.05, workspace=WORKSPACE)
    with pytest.raises(InvalidInputError, match="capture"):
        plan_seen(robot, perception, start, goal, "camera")
    with pytest.raises(InvalidInputError, match="rounds"):
        plan_seen(robot, perception, start, goal, lambda f, q: None, rounds=-1)
    for name, bad in (("views_per_round", 0), ("samples", 2.5), ("aimed", -1), ("aimed", True)):
        with pytest.raises(InvalidInputError, match=f"{name}.*whole number"):
            plan_seen(robot, perception, start, goal, lambda f, q: None, **{name: bad})


def test_a_view_into_nothing_unshadows_only_from_known_space_and_not_behind_the_robot() -> None:
    """A wall shadows what is behind it; the wall gone (the scene changed), a camera above looking down through that
    space into nothing unshadows it, but not through pixels of the robot's own bodies, and not from a camera that
    stands in unknown space of the region."""
    from taplan.scene.camera import look_at
    from taplan.scene.occupancy import OccupancyGrid
    from taplan.scene.raycast import render_depth

    region = ((0.0, -0.5, -0.5), (1.0, 0.5, 0.5))
    wall = Scene()
    wall.add("wall", Box((0.02, 0.4, 0.4)), ([0.6, 0.0, 0.0], [0, 0, 0, 1]))
    behind = np.array([[0.8, 0.0, 0.0]])

    def shadowed_grid() -> OccupancyGrid:
        grid = OccupancyGrid(0.02, region=region)
        T = look_at([0.05, 0.0, 0.0], [1.0, 0.0, 0.0])
        depth = render_depth(SMALL, T, wall)
        grid.mark_seen_free(depth, SMALL.intrinsics, T, margin=0.02, max_range=3.0)
        assert grid.shadowed[grid.keys(behind)[0]].all()
        return grid

    above = look_at([0.8, 0.0, 0.8], [0.8, 0.0, 0.0])  # outside the region, looking down
    nothing = np.full((SMALL.height, SMALL.width), np.nan, dtype=np.float32)
    grid = shadowed_grid()
    assert grid.unshadow_seen_into_nothing(nothing, SMALL.intrinsics, above, max_range=3.0) > 0
    assert not grid.shadowed[grid.keys(behind)[0]].any()
    key = grid.keys(behind)[0]
    assert not grid.free[key].any() and key[0] not in set(grid.unknown_keys("occluded").tolist())  # unknown, not free

    grid = shadowed_grid()  # the robot's own pixels in the middle of the image hide what is behind them
    own = np.zeros((SMALL.height, SMALL.width), dtype=bool)
    own[40:80, 60:100] = True
    grid.unshadow_seen_into_nothing(nothing, SMALL.intrinsics, above, max_range=3.0, ignore=own)
    assert grid.shadowed[grid.keys(behind)[0]].all()

    grid = shadowed_grid()  # a camera inside the region's unknown space (it may stand inside an unseen object)
    inside = look_at([0.8, 0.0, 0.3], [0.8, 0.0, 0.0])
    assert grid.unshadow_seen_into_nothing(nothing, SMALL.intrinsics, inside, max_range=3.0) == 0
    assert grid.shadowed[grid.keys(behind)[0]].all()
