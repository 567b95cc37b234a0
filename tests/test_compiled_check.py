"""The sampler's compiled clearance test (taplan.planning.compiled_check.ClearanceCheck on the numba kernel of
taplan.planning.clearance_kernel): the verdicts of the world's distances and of coal with a security margin over
every active pair, on every benchmark family, one arm and both, on near misses 1e-7 m either side of the clearance,
along motions in the same order with the same early exit, and with the pairs only coal can answer (attached
objects, meshes) beside it."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import taplan
from benchmarks._scenes import problems
from taplan.errors import InvalidInputError
from taplan.planning.compiled_check import ClearanceCheck, _bisection_order, _geometry
from taplan.scene import Box, CollisionWorld, Cylinder, HalfSpace, Mesh, Scene, Sphere


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


@pytest.fixture(scope="module")
def suite() -> list:
    return problems(13, 0)  # one problem of each benchmark family


def _active(robot: taplan.Robot, arms: tuple[str, ...]) -> np.ndarray:
    return np.concatenate([robot.group(a).indices for a in arms])


def _near(robot: taplan.Robot, start: np.ndarray, active: np.ndarray, rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` states about ``start`` with the ``active`` joints moved (within the planning limits)."""
    limits = robot.planning_limits
    Q = np.repeat(start[None], n, axis=0)
    Q[:, active] += rng.normal(0.0, 0.6, (n, len(active)))
    return np.clip(Q, limits.lower, limits.upper)


def _lowest(world: CollisionWorld, q: np.ndarray, pairs: set) -> tuple[float, tuple[str, str]]:
    """The smallest distance [m] of the tested ``pairs`` at ``q`` by the world's (exact) distances, and its pair."""
    d = world.distances(q, jacobian=False)
    return min(((x, p) for p, x in zip(d.pairs, d.distance, strict=True) if p in pairs), default=(np.inf, ("", "")))


def _coal_clear(world: CollisionWorld, q: np.ndarray, clearance: float, pairs: set) -> bool:
    """coal with ``security_margin = clearance`` over every tested pair (the test's former implementation)."""
    built = _geometry(world)
    data = pin.GeometryData(built.geometry)
    for index, pair in enumerate(built.pairs):
        if pair not in pairs:
            data.deactivateCollisionPair(index)
    for request in data.collisionRequests:
        request.security_margin = clearance
    model = world.robot.model
    return not pin.computeCollisions(model, model.createData(), built.geometry, data, q, True)


@pytest.mark.parametrize("arms", [("right",), ("left", "right")])
def test_verdicts_equal_the_worlds_distances_and_coal_on_every_family(robot, suite, arms) -> None:
    rng = np.random.default_rng(11)
    active = _active(robot, arms)
    outcomes = []
    for problem in suite:
        world = CollisionWorld(robot, problem.scene)
        for clearance in (0.0, 0.01, 0.03):
            check = ClearanceCheck(world, clearance, active)
            # every pair of the benchmark's scenes is compiled but the attached objects' (coal's)
            assert check.ready and (check.geometry is None) == (not problem.scene.attached)
            pairs = set(check.pairs)
            for q in _near(robot, problem.start, active, rng, 12):
                lowest = _lowest(world, q, pairs)[0]
                got = check(q)
                if abs(lowest - clearance) > 1e-9:  # [m]
                    assert got == (lowest >= clearance), (problem.family, clearance, lowest)
                    assert got == _coal_clear(world, q, clearance, pairs), (problem.family, clearance, lowest)
                outcomes.append(got)
    assert 0.2 < np.mean(outcomes) < 0.8  # both answers, often


def _boundary(world, check, q_clear, q_blocked, target):
    """A state on the segment from ``q_clear`` to ``q_blocked`` whose lowest tested distance is ``target`` [m] to
    1e-9 m (bisection), with that distance and pair."""
    pairs = set(check.pairs)
    lo, hi = 0.0, 1.0  # lowest(lo) > target >= lowest(hi)
    for _ in range(200):
        t = 0.5 * (lo + hi)
        q = q_clear + t * (q_blocked - q_clear)
        lowest, pair = _lowest(world, q, pairs)
        if abs(lowest - target) < 1e-9:
            return q, lowest, pair
        lo, hi = (t, hi) if lowest > target else (lo, t)
    raise AssertionError("no boundary state found")


@pytest.mark.parametrize("arms", [("right",), ("left", "right")])
def test_near_misses_within_and_beyond_the_clearance(robot, suite, arms) -> None:
    """States bisected onto the clearance's boundary, then 1e-7 m inside and beyond it: the compiled test answers as
    the world's distances on every family, for one arm and both."""
    rng = np.random.default_rng(5)
    active = _active(robot, arms)
    clearance = 0.01  # [m]
    kinds = set()
    for problem in suite:
        world = CollisionWorld(robot, problem.scene)
        check = ClearanceCheck(world, clearance, active)
        pairs = set(check.pairs)
        found = 0
        Q = _near(robot, problem.start, active, rng, 400)
        verdict = np.array([_lowest(world, q, pairs)[0] >= clearance for q in Q])
        for q_clear, q_blocked in zip(Q[verdict][:6], Q[~verdict][:6], strict=False):
            for offset in (1e-7, -1e-7):
                q, lowest, pair = _boundary(world, check, q_clear, q_blocked, clearance + offset)
                assert check(q) == (lowest >= clearance) == (offset > 0), (problem.family, pair, lowest)
                kinds.add("robot" if pair[1] in {b.name for b in world.bodies} else pair[1])
            found += 1
        assert found >= 3, problem.family
    assert "robot" in kinds and len(kinds) >= 6  # robot pairs and many obstacles' closed forms were on the boundary


def test_motions_test_the_same_states_in_the_same_order(robot, suite) -> None:
    """``motion`` answers as its states tested one by one, the end first then in bisection order, and counts the
    states it tested up to the first blocked one."""
    rng = np.random.default_rng(2)
    active = _active(robot, ("left", "right"))
    outcomes = []
    for problem in suite[:6]:
        world = CollisionWorld(robot, problem.scene)
        check = ClearanceCheck(world, 0.01, active)
        one = ClearanceCheck(world, 0.01, active)
        Q = _near(robot, problem.start, active, rng, 40)
        clear = Q[[one(q) for q in Q]]
        for q_a, q_b in zip(clear[:-1], clear[1:], strict=True):
            q_b = q_a + 0.4 * (q_b - q_a)
            spacing = 0.025
            count = max(1, int(np.ceil(float(check.reach @ np.abs(q_b - q_a)) / spacing)))
            states = q_a + _bisection_order(count)[:, None] * (q_b - q_a)
            verdicts = [one(q) for q in states]
            tested = count if all(verdicts) else verdicts.index(False) + 1
            before = check.checks
            assert check.motion(q_a, q_b, spacing) == all(verdicts)
            assert check.checks - before == tested
            outcomes.append(all(verdicts))
    assert 3 <= sum(outcomes) <= len(outcomes) - 3


def test_pairs_without_a_closed_form_stay_with_coal(robot) -> None:
    """An attached cup and a mesh: their pairs are coal's (security margin), the others compiled; together they
    answer as the world's distances, for one arm and both, and the right arm's test leaves the left's pairs out."""
    cube = Mesh(
        np.array([[x, y, z] for x in (-0.04, 0.04) for y in (-0.04, 0.04) for z in (-0.04, 0.04)], dtype=float),
        np.array(
            [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
             [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
        ),
    )  # fmt: skip
    scene = Scene()
    scene.add("floor", HalfSpace(), ([0, 0, -0.9], [0, 0, 0, 1]))
    scene.add("table", Box((0.6, 1.2, 0.04)), ([0.55, 0.0, -0.42], [0, 0, 0, 1]))
    scene.add("ball", Sphere(0.08), ([0.45, 0.3, -0.1], [0, 0, 0, 1]))
    scene.add("pole", Cylinder(0.01, 1.0), ([0.4, -0.3, -0.3], [0, 0, 0, 1]))
    scene.add("block", cube, ([0.4, 0.1, -0.2], [0, 0, 0, 1]))
    scene.attach("cup", Cylinder(0.035, 0.12), "right_tcp", ([0, 0, 0.06], [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    rng = np.random.default_rng(3)
    for arms in (("right",), ("left", "right")):
        active = _active(robot, arms)
        check = ClearanceCheck(world, 0.01, active)
        assert check.geometry is not None
        coal_pairs = {p for p in check.pairs if "cup" in p or "block" in p}
        assert coal_pairs and all(p in check.pairs for p in coal_pairs)
        if arms == ("right",):
            assert not any(p[0].startswith("left") and p[1] in {"table", "block"} for p in check.pairs)
        pairs = set(check.pairs)
        outcomes = []
        for q in _near(robot, robot.home, active, rng, 150):
            lowest, pair = _lowest(world, q, pairs)
            if abs(lowest - 0.01) > 1e-6:  # [m]: GJK on the mesh and the cup iterates to ~1e-7
                assert check(q) == (lowest >= 0.01), (pair, lowest)
                outcomes.append((lowest >= 0.01, pair in coal_pairs))
        assert 0 < sum(o for o, _ in outcomes) < len(outcomes)
        assert any(not o and c for o, c in outcomes)  # a coal pair was the blocking one


def test_without_native_code_the_kinematics_come_from_pinocchio(robot, suite, monkeypatch) -> None:
    """No C compiler (``TAPLAN_NATIVE=0``): the engine's pinocchio kinematics for every state, the same verdicts."""
    problem = suite[5]
    native = ClearanceCheck(CollisionWorld(robot, problem.scene), 0.01)
    monkeypatch.setenv("TAPLAN_NATIVE", "0")
    plain = ClearanceCheck(CollisionWorld(robot, problem.scene), 0.01)
    assert native._native is not None and plain._native is None
    rng = np.random.default_rng(4)
    Q = _near(robot, problem.start, _active(robot, ("left", "right")), rng, 60)
    assert [native(q) for q in Q] == [plain(q) for q in Q]
    assert [native.motion(a, b, 0.02) for a, b in zip(Q[:-1], Q[1:], strict=True)] == [
        plain.motion(a, b, 0.02) for a, b in zip(Q[:-1], Q[1:], strict=True)
    ]


@pytest.mark.parametrize("clearance", [-0.01, float("nan"), float("inf"), "1 cm"])
def test_a_clearance_must_be_a_finite_distance(robot, clearance) -> None:
    with pytest.raises(InvalidInputError, match="clearance"):
        ClearanceCheck(CollisionWorld(robot), clearance)


def test_the_positions_only_kinematics_equal_the_engines(robot) -> None:
    """``end_point_kernel`` (no Jacobians) gives the end points of the engine's kinematics (with them)."""
    from taplan.scene.engine import end_point_kernel

    world = CollisionWorld(robot)
    kernel = end_point_kernel(world)
    if kernel is None:
        pytest.skip("no C compiler: native kernels are off")
    assert end_point_kernel(CollisionWorld(robot)) is kernel  # shared by the worlds of one robot and body set
    Q = np.random.default_rng(8).uniform(-2.0, 2.0, (20, robot.nq))
    ends, _ = world.engine().segments(Q, jacobian=True)
    q_in, e_out = kernel._keep[0][0], kernel._keep[1][0]
    for q, expected in zip(Q, ends, strict=True):
        q_in[:] = q
        kernel()
        assert np.abs(e_out.reshape(-1, 2, 3) - expected).max() < 1e-12  # [m]
