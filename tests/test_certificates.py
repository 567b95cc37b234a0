"""Batched certificates: check_segments agrees with one-at-a-time checks and with dense sampling; a straight plan's
timing reuses its segment certificate only when it stays on the segment."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from taplan.planning import check_segment, check_segments, plan_motion, verify_trajectory
from taplan.planning.motion import _on_certified_segment
from taplan.scene import Box, CollisionWorld, HalfSpace, Scene
from taplan.timing import jerk_limited

MARGIN = 0.01  # [m]


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


@pytest.fixture(scope="module")
def world(robot) -> CollisionWorld:
    scene = Scene()
    scene.add("floor", HalfSpace(), ([0.0, 0.0, -1.0], [0, 0, 0, 1]))
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.45], [0, 0, 0, 1]))
    scene.add("panel", Box((0.5, 0.02, 0.5)), ([0.5, 0.0, -0.2], [0, 0, 0, 1]))
    return CollisionWorld(robot, scene)


def _segments(robot: taplan.Robot, world: CollisionWorld, count: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    limits = robot.planning_limits
    starts, ends = [], []
    while len(starts) < count:
        a, b = robot.home.copy(), robot.home.copy()
        for q in (a, b):
            q[robot.group("right").indices] += rng.uniform(-0.8, 0.8, 7)
            np.clip(q, limits.lower, limits.upper, out=q)
        if world.min_distance(a)[0] > MARGIN and world.min_distance(b)[0] > MARGIN:
            starts.append(a)
            ends.append(b)
    return np.array(starts), np.array(ends)


def test_batched_segment_checks_agree_with_single_checks_and_dense_sampling(robot, world) -> None:
    starts, ends = _segments(robot, world, 12)
    batch = check_segments(world, starts, ends, MARGIN)
    verdicts = [c.valid for c in batch]
    assert any(verdicts) and not all(verdicts)  # both outcomes exercised
    for a, b, got in zip(starts, ends, batch, strict=True):
        assert got.valid == check_segment(world, a, b, MARGIN).valid
        if got.valid:  # the certificate holds between its evaluations: margin / 2 everywhere
            lowest = min(world.min_distance(a + s * (b - a))[0] for s in np.linspace(0.0, 1.0, 201))
            assert lowest >= MARGIN / 2 - 1e-9


def test_a_straight_plan_reuses_its_segment_certificate_only_on_the_segment(robot, world) -> None:
    starts, ends = _segments(robot, world, 12)
    k = next(i for i, c in enumerate(check_segments(world, starts, ends, MARGIN)) if c.valid)
    plan = plan_motion(robot, starts[k], ends[k], world=world, margin=MARGIN)
    assert plan.report.stage == "straight"
    assert verify_trajectory(world, plan.trajectory, floor=MARGIN / 4, hold=starts[k]).collision_free
    assert _on_certified_segment(world, plan.trajectory, [starts[k], ends[k]], MARGIN)
    # a motion through a point 0.2 rad off the segment is not on it
    middle = (starts[k] + ends[k]) / 2
    middle[robot.group("right").indices[1]] += 0.2
    detour = jerk_limited(np.array([starts[k], middle, ends[k]]), robot.planning_limits).trajectory
    assert not _on_certified_segment(world, detour, [starts[k], ends[k]], MARGIN)


def test_segment_checks_from_known_distances_are_sound_and_agree(robot, world) -> None:
    from taplan.planning.verify import KnownDistances

    starts, ends = _segments(robot, world, 12)
    fractions = np.array([0.0, 0.5, 1.0])
    configurations = (starts[:, None] + fractions[None, :, None] * (ends - starts)[:, None]).reshape(-1, robot.nq)
    batch = world.distance_matrix(configurations)  # every pair, exact
    known = KnownDistances(fractions, batch.pairs, batch.distance.reshape(len(starts), 3, -1), batch.travel)
    reused = check_segments(world, starts, ends, MARGIN, points=MARGIN / 2, known=known)
    fresh = check_segments(world, starts, ends, MARGIN, points=MARGIN / 2)
    assert [c.valid for c in reused] == [c.valid for c in fresh]
    assert any(c.valid for c in reused) and not all(c.valid for c in reused)
    # the known first level is not evaluated again: fewer evaluations where a segment is certified
    assert sum(c.evaluations for c in reused) < sum(c.evaluations for c in fresh)
    for a, b, got in zip(starts, ends, reused, strict=True):
        if got.valid:
            lowest = min(world.min_distance(a + s * (b - a))[0] for s in np.linspace(0.0, 1.0, 201))
            assert lowest >= MARGIN / 2 - 1e-9
    with pytest.raises(taplan.errors.InvalidInputError, match="known"):
        check_segments(world, starts[:2], ends[:2], MARGIN, known=known)  # distances of 12 segments for 2


def test_an_uncertified_interval_is_split_into_the_pieces_its_closest_pair_needs() -> None:
    from taplan.planning.verify import MAX_PIECES, _split

    a, b = np.array([0.0, 0.0, 0.5]), np.array([1.0, 1.0, 0.75])
    d_a = np.array([[0.02, 1.0], [0.0102, 1.0], [0.02, 1.0]])  # [m], two pairs
    d_b = np.array([[0.02, 1.0], [0.0102, 1.0], [0.02, 1.0]])
    rate = np.array([[0.06, 0.0], [1.0, 0.0], [0.001, 0.0]])  # [m per unit of the parameter]
    seen = []

    def evaluate(curve: np.ndarray, s: np.ndarray) -> np.ndarray:
        seen.append(s.copy())
        return np.column_stack([0.02 + s, np.ones_like(s)])

    curve, lo, hi, d_lo, d_hi = _split(np.array([0, 1, 2]), a, b, d_a, d_b, rate, 0.005, evaluate, 2)
    counts = [int(np.sum(curve == k)) for k in range(3)]
    # pieces = ceil(1.25 * rate * length / (2 * (mean - floor))): 0.06 / 0.03 -> 3; 1.0 / 0.0104 -> capped; halving
    assert counts == [3, MAX_PIECES, 2]
    for k in range(3):  # contiguous pieces from a to b, the distances at their ends those evaluated there
        pieces = np.flatnonzero(curve == k)
        assert lo[pieces[0]] == a[k] and hi[pieces[-1]] == b[k]
        np.testing.assert_array_equal(hi[pieces[:-1]], lo[pieces[1:]])
        np.testing.assert_allclose(np.diff(np.append(lo[pieces], b[k])), (b[k] - a[k]) / counts[k], atol=1e-15)
        inner = pieces[1:]
        np.testing.assert_allclose(d_lo[inner, 0], 0.02 + lo[inner], atol=1e-15)
    assert len(seen) == 1  # every new point in one evaluation


def test_later_levels_evaluate_only_the_pairs_not_yet_certified_and_stay_sound(
    robot, world, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A certificate's later levels evaluate only the pairs some interval still needs: the same verdicts as
    evaluating every pair, far fewer pair evaluations, and sound by dense sampling with coal (no engine)."""
    starts, ends = _segments(robot, world, 12)
    reference = CollisionWorld(robot, world.scene, engine=False)
    limits = robot.planning_limits
    paths = [np.array([a, (a + b) / 2 + 0.1, b]) for a, b in zip(starts[:6], ends[:6], strict=True)]
    trajectories = [jerk_limited(path, limits).trajectory for path in paths]
    evaluated = {"subset": 0, "full": 0}
    pair_distances, distance_matrix = world.pair_distances, world.distance_matrix

    def counted_subset(Q: np.ndarray, pairs: tuple | None = None, **kwargs: object) -> object:
        out = pair_distances(Q, pairs, **kwargs)
        evaluated["subset"] += 0 if out is None else out.distance.size
        return out

    def counted_full(Q: np.ndarray, **kwargs: object) -> object:
        out = distance_matrix(Q, **kwargs)
        evaluated["full"] += out.distance.size
        return out

    def run() -> tuple[list[bool], list[bool]]:
        segments = [c.valid for c in check_segments(world, starts, ends, MARGIN)]
        timed = [verify_trajectory(world, t, floor=MARGIN / 4).collision_free for t in trajectories]
        return segments, timed

    monkeypatch.setattr(world, "distance_matrix", counted_full)
    monkeypatch.setattr(world, "pair_distances", counted_subset)
    subset = run()
    with_subsets = dict(evaluated)
    monkeypatch.setattr(world, "pair_distances", lambda *args, **kwargs: None)  # every level evaluates every pair
    evaluated.update(subset=0, full=0)
    full = run()
    assert subset == full
    assert any(subset[0]) and not all(subset[0]) and any(subset[1])
    assert with_subsets["subset"] > 0
    assert with_subsets["subset"] + with_subsets["full"] < 0.75 * evaluated["full"]
    for (a, b), valid in zip(zip(starts, ends, strict=True), subset[0], strict=True):
        if valid:
            lowest = min(reference.min_distance(a + s * (b - a))[0] for s in np.linspace(0.0, 1.0, 301))
            assert lowest >= MARGIN / 2 - 1e-9
    for trajectory, valid in zip(trajectories, subset[1], strict=True):
        if valid:
            lowest = min(reference.min_distance(trajectory(t))[0] for t in np.linspace(0, trajectory.duration, 601))
            assert lowest > MARGIN / 4 - 1e-9


def test_pairs_of_still_bodies_are_evaluated_once_per_curve(robot, world, monkeypatch: pytest.MonkeyPatch) -> None:
    """A right-arm trajectory: pairs whose members no moving joint carries (the left arm, the torso, the head) keep
    their distance, so only the first configuration evaluates them; the verdict is the one of evaluating every
    pair everywhere."""
    from taplan.planning.motion import _full_trajectory

    starts, ends = _segments(robot, world, 4)
    arm = robot.group("right").indices
    waypoints = np.array([starts[0], (starts[0] + ends[0]) / 2 + 0.1, ends[0]])[:, arm]
    part = jerk_limited(waypoints, robot.planning_limits.subset(robot.group("right").joint_names)).trajectory
    trajectory = _full_trajectory(part, robot.joint_names, arm, starts[0])  # as plan_motion embeds one arm's motion
    requests: list[tuple[int, object]] = []
    pair_distances = world.pair_distances

    def spy(Q: np.ndarray, pairs: tuple | None = None, **kwargs: object) -> object:
        requests.append((len(Q), pairs))
        return pair_distances(Q, pairs, **kwargs)

    monkeypatch.setattr(world, "pair_distances", spy)
    check = verify_trajectory(world, trajectory, floor=MARGIN / 4)
    assert requests[0] == (1, None)  # the first configuration: every pair
    right = {body.name for body in world.bodies if body.name.startswith("right_")}
    assert len(requests) > 1
    for _, pairs in requests[1:]:
        assert pairs is not None and all(a in right or b in right for a, b in pairs)
    monkeypatch.setattr(world, "pair_distances", lambda *args, **kwargs: None)
    full = verify_trajectory(world, trajectory, floor=MARGIN / 4)
    assert (check.collision_free, check.min_clearance) == (full.collision_free, pytest.approx(full.min_clearance))


def _polylines(
    robot: taplan.Robot, world: CollisionWorld, count: int, vertices: int, step: float = 0.25
) -> list[np.ndarray]:
    """Right-arm polylines (edges up to ``step`` [rad] per joint) whose vertices keep the certificate's points."""
    rng = np.random.default_rng(11)
    limits = robot.planning_limits
    arm = robot.group("right").indices
    out = []
    while len(out) < count:
        q = robot.home.copy()
        q[arm] += rng.uniform(-0.8, 0.8, 7)
        path = [np.clip(q, limits.lower, limits.upper)]
        for _ in range(vertices - 1):
            q = path[-1].copy()
            q[arm] += rng.uniform(-step, step, 7)
            path.append(np.clip(q, limits.lower, limits.upper))
        if all(world.min_distance(v)[0] > MARGIN / 2 + 2e-4 for v in path):
            out.append(np.array(path))
    return out


def test_a_polyline_certificate_is_sound_and_agrees_with_its_edges_certificates(
    robot, world, monkeypatch: pytest.MonkeyPatch
) -> None:
    """check_path (the vertices evaluated once, edges split where needed) gives the verdict of certifying every
    edge with check_segments on these paths, with fewer configurations evaluated, and holds by dense sampling with
    coal (no engine): margin / 2 between the evaluations."""
    from taplan.planning.verify import check_path

    reference = CollisionWorld(robot, world.scene, engine=False)
    paths = _polylines(robot, world, 10, 6, step=0.5)
    evaluated = [0]
    pair_distances = world.pair_distances

    def counted(Q: np.ndarray, pairs: tuple | None = None, **kwargs: object) -> object:
        evaluated[0] += len(Q)
        return pair_distances(Q, pairs, **kwargs)

    monkeypatch.setattr(world, "pair_distances", counted)
    whole, per_edge, counts = [], [], []
    for path in paths:
        evaluated[0] = 0
        whole.append(check_path(world, path, MARGIN, points=MARGIN / 2).valid)
        counts.append(evaluated[0])
        evaluated[0] = 0
        checks = check_segments(world, path[:-1], path[1:], MARGIN, points=MARGIN / 2)
        per_edge.append(all(c.valid for c in checks))
        counts[-1] -= evaluated[0]
    assert whole == per_edge
    assert any(whole) and not all(whole)  # both outcomes exercised
    assert sum(counts) < 0  # fewer configurations evaluated in all
    for path, valid in zip(paths, whole, strict=True):
        if valid:
            for a, b in zip(path[:-1], path[1:], strict=True):
                lowest = min(reference.min_distance(a + s * (b - a))[0] for s in np.linspace(0.0, 1.0, 41))
                assert lowest >= MARGIN / 2 - 1e-9


def test_a_polyline_through_an_obstacle_or_malformed_is_refused(robot, world) -> None:
    from taplan.planning.verify import check_path

    paths = _polylines(robot, world, 40, 6)
    clear = next(p for p in paths if check_path(world, p, MARGIN, points=MARGIN / 2).valid)
    # a vertex moved into the table: the edges into and out of it are refused
    inside = next(
        q
        for q in (clear[2] + np.eye(robot.nq)[j] * dq for j in robot.group("right").indices for dq in (0.6, -0.6, 1.2))
        if world.min_distance(q)[0] < 0
    )
    blocked = clear.copy()
    blocked[2] = inside
    check = check_path(world, blocked, MARGIN, points=MARGIN / 2)
    assert not check.valid and check.clearance < MARGIN / 2
    # a zero-length edge (a repeated vertex) is certified by its ends
    assert check_path(world, np.insert(clear, 3, clear[3], axis=0), MARGIN, points=MARGIN / 2).valid
    with pytest.raises(taplan.errors.InvalidInputError, match="path"):
        check_path(world, clear[:1], MARGIN)
    with pytest.raises(taplan.errors.InvalidInputError, match="margin"):
        check_path(world, clear, -1.0)
