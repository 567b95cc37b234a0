"""The smoothing of sampled paths (taplan.planning.rrt.smooth_path and plan_motion's sampled route): the arms moved
together, shortcuts, blended corners, every new edge passing the compiled test, the result evenly resampled and
certified, and the order of the stages (the optimiser before the sampler gets a bounded number of QPs)."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

import taplan
from taplan.errors import PlanningError
from taplan.planning import motion, plan_motion
from taplan.planning.compiled_check import ClearanceCheck
from taplan.planning.rrt import (
    SPACING_SHARE,
    blend_corners,
    rrt_connect_shrinking,
    smooth_path,
    spline_path,
    synchronise,
)
from taplan.planning.verify import check_segment
from taplan.scene import Box, CollisionWorld, Scene

ACROSS = [-0.841, -1.177, 1.323, -1.504, -0.348, -0.033, -0.58]  # the right arm reaching across the box
MARGIN = 0.01  # [m]


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _box_on_table(robot: taplan.Robot) -> CollisionWorld:
    """The straight segment home -> ACROSS passes through the box."""
    scene = Scene()
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    scene.add("box", Box((0.12, 0.2, 0.16)), ([0.5, 0.0, -0.32], [0, 0, 0, 1]))
    return CollisionWorld(robot, scene)


def _two_arm_goal(robot: taplan.Robot) -> np.ndarray:
    goal = robot.home.copy()
    goal[robot.group("right").indices] = ACROSS
    goal[robot.group("left").indices] = robot.home[robot.group("left").indices] + [0.3, 0.2, -0.2, 0.3, 0.0, 0.2, 0.0]
    return goal


class _Recorder:
    """``valid_motion`` of the sampler (the compiled test at the sampler's spacing) that records every motion it
    was asked about and its answer."""

    def __init__(self, world: CollisionWorld, active: np.ndarray) -> None:
        self.check = ClearanceCheck(world, MARGIN, active)
        self.asked: list[tuple[np.ndarray, np.ndarray, bool]] = []

    def __call__(self, a: np.ndarray, b: np.ndarray) -> bool:
        ok = self.check.motion(a, b, SPACING_SHARE * MARGIN)
        self.asked.append((a.copy(), b.copy(), ok))
        return ok

    def passed(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Whether the motion a -> b, or one that contains it (a longer motion on the same segment), passed."""
        for x, y, ok in self.asked:
            if not ok:
                continue
            d = y - x
            if np.abs(d).max() == 0:
                continue
            ta = _parameter(x, d, a)
            tb = _parameter(x, d, b)
            if ta is not None and tb is not None and min(ta, tb) >= -1e-9 and max(ta, tb) <= 1 + 1e-9:
                return True
        return False


def _parameter(x: np.ndarray, d: np.ndarray, q: np.ndarray) -> float | None:
    """t with q = x + t d (to 1e-9 rad), else None."""
    t = float((q - x) @ d / (d @ d))
    return t if np.abs(x + t * d - q).max() < 1e-9 else None


def _on_an_edge(path: list[np.ndarray], a: np.ndarray, b: np.ndarray) -> bool:
    for x, y in zip(path[:-1], path[1:], strict=True):
        ta, tb = _parameter(x, y - x, a), _parameter(x, y - x, b)
        if ta is not None and tb is not None and min(ta, tb) >= -1e-9 and max(ta, tb) <= 1 + 1e-9:
            return True
    return False


def _length(path: list[np.ndarray]) -> float:
    return float(sum(np.linalg.norm(b - a) for a, b in zip(path[:-1], path[1:], strict=True)))


def test_one_arm_after_the_other_becomes_both_at_once(robot: taplan.Robot) -> None:
    """In free space a path that moves the left arm, then the right, is replaced by one that moves both together;
    each arm's own positions stay on its own polyline (the same geometric path per arm)."""
    world = CollisionWorld(robot, Scene())
    left, right = np.array(robot.group("left").indices), np.array(robot.group("right").indices)
    goal = _two_arm_goal(robot)
    middle = robot.home.copy()
    middle[left] = goal[left]
    bend = middle.copy()
    bend[right] = (robot.home[right] + goal[right]) / 2 + 0.2  # the right arm's own path has a corner
    path = [robot.home.copy(), middle, bend, goal]
    valid = _Recorder(world, np.concatenate([left, right]))
    out = synchronise(valid, path, [left, right])
    assert out is not path
    np.testing.assert_allclose(out[0], path[0], atol=0)
    np.testing.assert_allclose(out[-1], path[-1], atol=0)
    for a, b in zip(out[:-1], out[1:], strict=True):
        assert np.abs(b[left] - a[left]).max() > 0 and np.abs(b[right] - a[right]).max() > 0  # both move
        assert valid.passed(a, b)
    # the left arm goes straight (its own path is one segment), the right arm passes its corner
    for q in out:
        t = _parameter(robot.home[left], goal[left] - robot.home[left], q[left])
        assert t is not None and -1e-9 <= t <= 1 + 1e-9
    assert any(np.abs(q[right] - bend[right]).max() < 1e-9 for q in out)


def test_synchronise_keeps_the_path_when_a_joint_edge_is_refused(robot: taplan.Robot) -> None:
    left, right = np.array(robot.group("left").indices), np.array(robot.group("right").indices)
    goal = _two_arm_goal(robot)
    middle = robot.home.copy()
    middle[left] = goal[left]
    path = [robot.home.copy(), middle, goal]

    def one_arm_only(a: np.ndarray, b: np.ndarray) -> bool:
        return np.abs(b[left] - a[left]).max() == 0 or np.abs(b[right] - a[right]).max() == 0

    assert synchronise(one_arm_only, path, [left, right]) is path


def test_smoothed_path_is_shorter_and_every_new_edge_passed_the_compiled_test(robot: taplan.Robot) -> None:
    """The sampler's path around the box made shorter: the ends are kept exactly, every edge of the result lies on
    a motion the compiled test passed (or on the sampler's certified edges), and it is certified by conservative
    advancement."""
    world = _box_on_table(robot)
    right = np.array(robot.group("right").indices)
    goal = robot.home.copy()
    goal[right] = ACROSS
    limits = robot.planning_limits
    found = rrt_connect_shrinking(world, robot.home, goal, right, limits.lower, limits.upper, (MARGIN,), max_time=30.0)
    assert found is not None
    path = found[0]
    valid = _Recorder(world, right)
    smooth = smooth_path(valid, path, right, [right], rng=np.random.default_rng(1))
    np.testing.assert_allclose(smooth[0], path[0], atol=0)
    np.testing.assert_allclose(smooth[-1], path[-1], atol=0)
    assert _length(smooth) <= _length(path) + 1e-9
    for a, b in zip(smooth[:-1], smooth[1:], strict=True):
        assert np.abs(b - a)[np.setdiff1d(np.arange(robot.nq), right)].max() == 0  # only the active joints move
        assert valid.passed(a, b) or _on_an_edge(path, a, b)  # new, or a piece of the sampler's own edges
        assert check_segment(world, a, b, MARGIN, points=MARGIN / 2).valid


def test_a_corner_is_blended_inside_its_triangle_or_kept(robot: taplan.Robot) -> None:
    right = np.array(robot.group("right").indices)
    corner = robot.home.copy()
    corner[right] += 0.6
    end = corner.copy()
    end[right[:3]] -= 1.0
    path = [robot.home.copy(), corner, end]
    blended = blend_corners(lambda a, b: True, path, right)
    assert len(blended) > 3 and not any(np.abs(q - corner).max() < 1e-9 for q in blended)
    # a quadratic Bezier between the points half the shorter edge from the corner on either edge, pulled by the
    # corner: each point is a convex combination of the three
    size = 0.5 * min(np.linalg.norm(corner - path[0]), np.linalg.norm(end - corner))
    a = corner + size * (path[0] - corner) / np.linalg.norm(corner - path[0])
    b = corner + size * (end - corner) / np.linalg.norm(end - corner)
    np.testing.assert_allclose(blended[1], a, atol=1e-12)
    np.testing.assert_allclose(blended[-2], b, atol=1e-12)
    for q in blended[1:-1]:
        weights, *_ = np.linalg.lstsq(np.column_stack([a, corner, b]), q, rcond=None)
        assert weights.min() >= -1e-9 and abs(weights.sum() - 1) < 1e-9
    assert blend_corners(lambda a, b: False, path, right) == path  # nothing fits: the corner stays


def test_sampled_plan_is_smoothed_certified_and_no_slower_than_unsmoothed(
    robot: taplan.Robot, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Both arms, the right one around the box: the plan's path is the smoothed one (evenly spaced waypoints, each
    at least the margin from everything), the timed trajectory keeps a quarter of the margin at 400 sampled
    instants, and it lasts less than the unsmoothed plan of the same search."""
    world = _box_on_table(robot)
    goal = _two_arm_goal(robot)
    plan = plan_motion(robot, robot.home, goal, world=world, stages=("rrt-connect",), max_time=20.0, seed=3)
    assert plan.report.stage == "rrt-connect" and plan.report.smoothed
    assert plan.report.stage_times["smooth"] > 0.0
    steps = np.linalg.norm(np.diff(plan.path, axis=0), axis=1)
    assert steps.max() <= motion.DENSIFY_STEP + 1e-9  # [rad] evenly resampled
    for q in plan.path:
        assert world.min_distance(q)[0] >= plan.report.margin - 1e-9
    index = robot.indices(plan.trajectory.joint_names)
    for t in np.linspace(0, plan.trajectory.duration, 400):
        q = robot.home.copy()
        q[index] = plan.trajectory(t)
        assert world.min_distance(q)[0] >= plan.report.margin / 4 - 1e-9
    np.testing.assert_allclose(plan.trajectory(plan.trajectory.duration)[index], goal[index], atol=1e-9)
    monkeypatch.setattr(motion, "SMOOTH_MIN", 1e6)
    raw = plan_motion(robot, robot.home, goal, world=world, stages=("rrt-connect",), max_time=20.0, seed=3)
    assert not raw.report.smoothed
    assert plan.trajectory.duration < raw.trajectory.duration


def test_the_optimiser_before_the_sampler_gets_a_bounded_number_of_qps(
    robot: taplan.Robot, monkeypatch: pytest.MonkeyPatch
) -> None:
    """When the sampler follows, the optimiser from the straight line may solve at most OPTIMIZE_ITERATIONS QPs
    (a stuck optimiser is left early, whatever the load); without the sampler it keeps its full count."""
    world = _box_on_table(robot)
    goal = robot.home.copy()
    goal[robot.group("right").indices] = ACROSS
    asked: list[int] = []
    real = motion.optimize_path

    def recording(*args, **options):  # noqa: ANN002, ANN003, ANN202 (a stand-in)
        asked.append(options.get("max_iterations", 30))
        return real(*args, **options)

    monkeypatch.setattr(motion, "optimize_path", recording)
    plan_motion(robot, robot.home, goal, world=world, max_time=10.0, seed=0)
    assert asked and asked[0] == motion.OPTIMIZE_ITERATIONS
    asked.clear()
    with contextlib.suppress(PlanningError):
        plan_motion(robot, robot.home, goal, world=world, stages=("straight", "optimization"), max_time=10.0)
    assert asked and asked[0] > motion.OPTIMIZE_ITERATIONS


def test_the_spline_spreads_a_corner_and_keeps_the_ends(robot: taplan.Robot) -> None:
    """A right-angle corner becomes a curve through evenly spaced points whose turn per point is small, from the
    first to the last configuration exactly; the joints that do not move keep their values; a refused spline leaves
    the path as it was."""
    right = np.array(robot.group("right").indices)
    corner = robot.home.copy()
    corner[right[0]] += 1.0
    end = corner.copy()
    end[right[1]] -= 1.0
    path = [robot.home.copy(), corner, end]
    curve = spline_path(lambda a, b: True, path, right)
    np.testing.assert_array_equal(curve[0], path[0])
    np.testing.assert_array_equal(curve[-1], path[-1])
    others = np.setdiff1d(np.arange(robot.nq), right)
    assert all(np.array_equal(q[others], robot.home[others]) for q in curve)
    steps = np.diff(np.array(curve)[:, right], axis=0)
    assert np.linalg.norm(steps, axis=1).max() <= 0.1 + 1e-9  # [rad] sampled finely
    unit = steps / np.linalg.norm(steps, axis=1)[:, None]
    turns = np.arccos(np.clip(np.sum(unit[:-1] * unit[1:], axis=1), -1.0, 1.0))
    assert max(turns) < np.pi / 8  # the 90 degree turn spread over many points
    assert spline_path(lambda a, b: False, path, right) is path


def test_the_sampled_path_is_certified_only_when_its_smoothed_path_is_not_used(
    robot: taplan.Robot, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The sampler hands its path over uncertified; the smoothed path carries the certificate. When smoothing gives
    nothing the sampled path is certified then, and when that certificate refuses an edge the sampler searches again
    certifying what it finds: every plan stays certified along its timed trajectory."""
    world = _box_on_table(robot)
    goal = robot.home.copy()
    goal[robot.group("right").indices] = ACROSS
    certified: list[int] = []
    real = motion.certify_path

    def counting(world, path, margin, deadline=float("inf")):  # noqa: ANN001, ANN202 (a stand-in)
        certified.append(len(path))
        return real(world, path, margin, deadline)

    monkeypatch.setattr(motion, "certify_path", counting)
    plan = plan_motion(robot, robot.home, goal, world=world, stages=("rrt-connect",), max_time=20.0, seed=0)
    assert plan.report.smoothed and len(certified) == 1 and certified[0] == len(plan.path)  # the smoothed one only

    def clearance(plan: motion.MotionPlan) -> float:
        index = robot.indices(plan.trajectory.joint_names)
        lowest = np.inf
        for t in np.linspace(0, plan.trajectory.duration, 200):
            q = robot.home.copy()
            q[index] = plan.trajectory(t)
            lowest = min(lowest, world.min_distance(q)[0])
        return lowest

    monkeypatch.setattr(motion, "_smooth_sampled", lambda *args: None)
    certified.clear()
    plan = plan_motion(robot, robot.home, goal, world=world, stages=("rrt-connect",), max_time=20.0, seed=0)
    assert not plan.report.smoothed and len(certified) == 1  # the sampled path, certified now
    assert clearance(plan) >= MARGIN / 4 - 1e-9

    refused: list[int] = []

    def refuse_once(world, path, margin, deadline=float("inf")):  # noqa: ANN001, ANN202 (a stand-in)
        if not refused:
            refused.append(len(path))
            return None
        return real(world, path, margin, deadline)

    monkeypatch.setattr(motion, "certify_path", refuse_once)
    searched: list[bool] = []
    real_find = motion._find_path

    def recording_find(*args, **options):  # noqa: ANN002, ANN003, ANN202 (a stand-in)
        searched.append(options.get("certify", True))
        return real_find(*args, **options)

    monkeypatch.setattr(motion, "_find_path", recording_find)
    plan = plan_motion(robot, robot.home, goal, world=world, stages=("rrt-connect",), max_time=20.0, seed=0)
    assert refused and searched == [False, True]  # searched again, certifying
    assert clearance(plan) >= MARGIN / 4 - 1e-9


def test_the_smoother_tests_at_its_own_spacing_and_its_path_is_certified_as_one_polyline(
    robot: taplan.Robot, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The smoother's compiled test spaces its states SMOOTH_SPACING_SHARE x the margin apart (coarser than the
    exploration's: the smoothed path is certified afterwards), and the smoothed path's certificate is the polyline
    one (check_path, valid at the first try): every edge keeps half the margin by dense sampling."""
    from taplan.planning import rrt, verify
    from taplan.planning.rrt import SMOOTH_SPACING_SHARE

    assert SMOOTH_SPACING_SHARE > SPACING_SHARE
    world = _box_on_table(robot)
    goal = _two_arm_goal(robot)
    spacings: list[float] = []
    polylines: list[bool] = []
    real_motion, real_check_path = ClearanceCheck.motion, verify.check_path

    def recording_motion(self, a, b, spacing):  # noqa: ANN001, ANN202 (a stand-in)
        spacings.append(spacing)
        return real_motion(self, a, b, spacing)

    def recording_check_path(*args, **options):  # noqa: ANN002, ANN003, ANN202 (a stand-in)
        found = real_check_path(*args, **options)
        polylines.append(found.valid)
        return found

    monkeypatch.setattr(rrt, "check_path", recording_check_path)
    sampled = motion._find_path
    monkeypatch.setattr(
        motion,
        "_find_path",
        lambda *args, **options: (sampled(*args, **options), spacings.clear(), polylines.clear())[0],
    )
    monkeypatch.setattr(ClearanceCheck, "motion", recording_motion)
    plan = plan_motion(robot, robot.home, goal, world=world, stages=("rrt-connect",), max_time=20.0, seed=3)
    assert plan.report.smoothed
    assert spacings and all(s == pytest.approx(SMOOTH_SPACING_SHARE * MARGIN) for s in spacings)  # the smoother's
    assert polylines == [True]  # certified as one polyline, no edge-by-edge pass
    for a, b in zip(plan.path[:-1], plan.path[1:], strict=True):
        lowest = min(world.min_distance(a + s * (b - a))[0] for s in np.linspace(0.0, 1.0, 11))
        assert lowest >= MARGIN / 2 - 1e-9
