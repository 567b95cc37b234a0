"""taplan.scene.engine: batched distances equal to the coal reference (CollisionWorld with engine=False) to 1e-9 m,
Jacobians equal to the reference and to finite differences, both kinematics paths, the world's batch entry points;
the compiled pair loops equal the numpy engine they replaced (tests/engine_reference.py) on every benchmark family."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import taplan
from taplan.scene import Box, Capsule, CollisionWorld, Cylinder, HalfSpace, Scene, Sphere
from taplan.scene.engine import DistanceEngine, _Kinematics, segment_box, segment_cylinder

DIST_TOL = 1e-9  # [m] engine vs coal (GJK/EPA tolerance tightened to 1e-12)
JAC_TOL = 1e-9  # [m/rad] where the witness points are unique
CYLINDER_JAC_TOL = 1e-5  # [m/rad] the searched witness on a cylinder is exact in distance, ~1e-6 in place
FD_TOL = 1e-5  # [m/rad] engine Jacobian vs central differences of the engine's own distances


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _quaternion(rng: np.random.Generator) -> list[float]:
    q = rng.normal(size=4)
    return (q / np.linalg.norm(q)).tolist()


def _scene(seed: int) -> Scene:
    """Every closed-form shape, rotated, in the arms' reach (many configurations penetrate some of them)."""
    rng = np.random.default_rng(seed)
    scene = Scene()
    scene.add("floor", HalfSpace(), ([0.0, 0.0, -0.9], [0, 0, 0, 1]))
    for k in range(4):
        xyz = rng.uniform([0.2, -0.5, -0.6], [0.6, 0.5, 0.1]).tolist()
        scene.add(f"box{k}", Box(tuple(rng.uniform(0.03, 0.3, 3))), (xyz, _quaternion(rng)))
    scene.add("ball", Sphere(0.07), ([0.35, 0.2, -0.3], [0, 0, 0, 1]))
    scene.add("stick", Capsule(0.04, 0.3), ([0.35, -0.25, -0.3], _quaternion(rng)))
    scene.add("pole", Cylinder(0.03, 0.6), ([0.4, 0.05, -0.3], _quaternion(rng)))
    scene.add("drum", Cylinder(0.12, 0.1), ([0.3, -0.1, -0.45], _quaternion(rng)))
    return scene


def _reference(robot: taplan.Robot, scene: Scene) -> CollisionWorld:
    world = CollisionWorld(robot, scene, engine=False)
    world._request.gjk_tolerance = 1e-12  # coal's default 1e-6 is the error of its cylinders, not the engine's
    world._request.epa_tolerance = 1e-12
    return world


def _configurations(robot: taplan.Robot, count: int, seed: int) -> np.ndarray:
    limits = robot.planning_limits
    rng = np.random.default_rng(seed)
    return limits.lower + rng.uniform(0, 1, (count, robot.nq)) * (limits.upper - limits.lower)


@pytest.mark.parametrize("seed", [0, 1])
def test_batch_equals_the_coal_reference(robot: taplan.Robot, seed: int) -> None:
    scene = _scene(seed)
    world, reference = CollisionWorld(robot, scene), _reference(robot, scene)
    Q = _configurations(robot, 60, seed)
    batch = world.engine().evaluate(Q)
    column = {pair: k for k, pair in enumerate(batch.pairs)}
    cylinders = {"pole", "drum"}
    penetrating = compared = 0
    for n, q in enumerate(Q):
        ref = reference.distances(q)
        assert set(ref.pairs) == set(batch.pairs)  # the same pairs: every robot pair, every moving body vs obstacle
        k = np.array([column[p] for p in ref.pairs])
        np.testing.assert_allclose(batch.distance[n, k], ref.distance, rtol=0, atol=DIST_TOL)
        np.testing.assert_allclose(batch.travel[k], ref.travel, rtol=0, atol=1e-12)
        clear = ref.distance > 1e-6  # penetrating pairs: coal's EPA witnesses are not unique
        penetrating += int(np.sum(~clear))
        for row, pair in zip(np.flatnonzero(clear), np.array(ref.pairs, dtype=object)[clear], strict=True):
            tolerance = CYLINDER_JAC_TOL if pair[1] in cylinders else JAC_TOL
            np.testing.assert_allclose(batch.jacobian[n, k[row]], ref.jacobian[row], rtol=0, atol=tolerance)
            np.testing.assert_allclose(batch.normal[n, k[row]], ref.normal[row], rtol=0, atol=1e-4)
            compared += 1
    assert penetrating > 0 and compared > 1000  # both regimes were exercised


def test_jacobian_matches_finite_differences(robot: taplan.Robot) -> None:
    scene = _scene(3)
    engine = CollisionWorld(robot, scene).engine()
    Q = _configurations(robot, 8, 3)
    h = 1e-6
    batch = engine.evaluate(Q)
    rng = np.random.default_rng(4)
    for n, q in enumerate(Q):
        dq = rng.normal(size=robot.nq)
        dq /= np.linalg.norm(dq)
        plus = engine.evaluate((q + h * dq)[None], jacobian=False).distance[0]
        minus = engine.evaluate((q - h * dq)[None], jacobian=False).distance[0]
        numeric = (plus - minus) / (2 * h)
        smooth = batch.distance[n] > 1e-3  # away from contact the distance is differentiable
        np.testing.assert_allclose((batch.jacobian[n] @ dq)[smooth], numeric[smooth], rtol=0, atol=FD_TOL)


def test_jacobian_rows_within_a_distance_equal_the_full_rows(robot: taplan.Robot) -> None:
    engine = CollisionWorld(robot, _scene(1)).engine()
    Q = _configurations(robot, 12, 5)
    full = engine.evaluate(Q)
    within = 0.05  # [m]
    near = engine.evaluate(Q, jacobian_within=within)
    np.testing.assert_array_equal(near.distance, full.distance)
    close = full.distance <= within
    assert 0 < close.sum() < close.size  # some rows computed, some left out
    np.testing.assert_allclose(near.jacobian[close], full.jacobian[close], rtol=0, atol=1e-15)
    assert np.all(near.jacobian[~close] == 0.0)
    assert np.any(full.jacobian[~close] != 0.0)


def test_bounded_pairs_keep_the_exact_ones_and_bound_the_others(robot: taplan.Robot) -> None:
    """With ``bound_beyond`` only the pairs the broad phase keeps are computed exactly (the others report their
    bounding spheres' gap): the kept ones equal the unbounded batch in every output, Jacobian rows included."""
    engine = CollisionWorld(robot, _scene(0)).engine()
    Q = _configurations(robot, 20, 7)
    beyond = 0.05  # [m]
    full = engine.evaluate(Q)
    bounded = engine.evaluate(Q, bound_beyond=beyond, jacobian_within=beyond)
    kept = bounded.distance <= beyond
    assert 0 < kept.sum() < kept.size  # both kinds present
    np.testing.assert_array_equal(bounded.distance[kept], full.distance[kept])
    for name in ("point_a", "point_b", "normal", "jacobian"):
        np.testing.assert_array_equal(getattr(bounded, name)[kept], getattr(full, name)[kept])
    assert np.all(bounded.distance[~kept] <= full.distance[~kept] + 1e-12)  # a lower bound [m]
    assert np.all(bounded.jacobian[~kept] == 0.0)


def test_native_and_pinocchio_kinematics_agree(robot: taplan.Robot) -> None:
    world = CollisionWorld(robot, _scene(0))
    engine = DistanceEngine(world)
    if engine._kinematics.native is None:
        pytest.skip("no C compiler: only the pinocchio path exists")
    Q = _configurations(robot, 5, 7)
    ends, rows = engine.segments(Q)
    fallback = _Kinematics.__new__(_Kinematics)
    fallback.world, fallback.model, fallback.nv, fallback.B = world, world.model, world.model.nv, len(world.bodies)
    ends_ref, rows_ref = fallback._pinocchio(Q, True)
    np.testing.assert_allclose(ends, ends_ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rows, rows_ref, rtol=0, atol=1e-12)


def test_world_batches_use_the_engine_and_match_single_calls(robot: taplan.Robot) -> None:
    scene = _scene(2)
    world, reference = CollisionWorld(robot, scene), _reference(robot, scene)
    Q = _configurations(robot, 10, 2)
    for q, got in zip(Q, world.distances_many(Q, cutoff=0.05), strict=True):
        ref = reference.distances(q, cutoff=0.05)
        assert got.pairs == ref.pairs  # same order: robot pairs, then obstacle-major
        np.testing.assert_allclose(got.distance, ref.distance, rtol=0, atol=DIST_TOL)
    matrix = world.distance_matrix(Q, bound_beyond=0.1)
    exact = world.distance_matrix(Q)
    assert np.all(matrix.distance <= exact.distance + 1e-12)  # the bound is a lower bound
    assert np.any(matrix.distance < exact.distance - 1e-3)  # and is used


def test_attached_objects_go_through_the_world(robot: taplan.Robot) -> None:
    scene = _scene(0)
    scene.attach("tool", Cylinder(0.03, 0.12), "left_tcp", ([0, 0, 0.06], [0, 0, 0, 1]))
    world, reference = CollisionWorld(robot, scene), _reference(robot, scene)
    world._request.gjk_tolerance = world._request.epa_tolerance = 1e-12  # both use coal for the attached pairs
    Q = _configurations(robot, 3, 9)
    matrix = world.distance_matrix(Q)
    assert any(pair[0] == "tool" for pair in matrix.pairs)
    column = {pair: k for k, pair in enumerate(matrix.pairs)}
    for n, q in enumerate(Q):
        single = reference.distances(q, jacobian=False)
        assert set(single.pairs) == set(matrix.pairs)
        got = matrix.distance[n, [column[p] for p in single.pairs]]
        np.testing.assert_allclose(got, single.distance, rtol=0, atol=DIST_TOL)
    bounded = world.distance_matrix(Q, bound_beyond=0.05)
    assert np.all(bounded.distance <= matrix.distance + 1e-12)  # the attached pairs' gaps are lower bounds too


def test_jacobian_batch_with_attached_objects_equals_the_single_queries(robot: taplan.Robot) -> None:
    """With an attached object the optimiser's batch (:meth:`CollisionWorld.jacobian_batch`) holds every pair of
    :meth:`CollisionWorld.distances_many` within the cutoff with the same distance and Jacobian row."""
    scene = _scene(0)
    scene.attach("tool", Cylinder(0.03, 0.12), "left_tcp", ([0, 0, 0.06], [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    Q = _configurations(robot, 12, 11)
    cutoff = 0.08  # [m]
    batch = world.jacobian_batch(Q, cutoff=cutoff)
    assert batch is not None and any(pair[0] == "tool" for pair in batch.pairs)
    column = {pair: k for k, pair in enumerate(batch.pairs)}
    tool_rows = 0
    for n, single in enumerate(world.distances_many(Q, cutoff=cutoff)):
        within = [batch.pairs[k] for k in np.flatnonzero(batch.distance[n] <= cutoff)]
        assert set(within) == set(single.pairs)
        k = np.array([column[p] for p in single.pairs], dtype=int)
        np.testing.assert_allclose(batch.distance[n, k], single.distance, rtol=0, atol=1e-12)  # [m]
        np.testing.assert_allclose(batch.jacobian[n, k], single.jacobian, rtol=0, atol=1e-12)  # [m/rad]
        tool_rows += sum(pair[0] == "tool" for pair in single.pairs)
        assert np.all(batch.jacobian[n, batch.distance[n] > cutoff] == 0.0)
    assert tool_rows > 0  # the attached object's rows were compared
    matrix = world.distance_matrix(Q, bound_beyond=cutoff)  # the same pairs, bounds and witnesses without rows
    assert matrix.pairs == batch.pairs
    np.testing.assert_array_equal(matrix.distance, batch.distance)
    tool = np.array([pair[0] == "tool" for pair in batch.pairs])
    clear = (batch.distance > 1e-6) & tool[None]
    gaps = np.linalg.norm(matrix.point_a - matrix.point_b, axis=-1)
    np.testing.assert_allclose(gaps[clear], matrix.distance[clear], rtol=0, atol=1e-9)  # witnesses d apart [m]


def _attached_pairs_one_by_one(world: CollisionWorld, q: np.ndarray) -> dict:
    """The attached object's pairs queried one at a time by coal (GJK/EPA tolerances 1e-12) at ``q``:
    {pair: distance}."""
    import coal
    import pinocchio as pin

    request = coal.DistanceRequest()
    request.enable_signed_distance = True
    request.gjk_tolerance = request.epa_tolerance = 1e-12
    pin.forwardKinematics(world.model, world.data, q)
    pin.updateFramePlacements(world.model, world.data)
    [att] = world._attached_items()
    T = world.data.oMf[att.frame].homogeneous @ att.pose
    transform = coal.Transform3s(T[:3, :3], T[:3, 3])
    out = {}
    for item in world._items:
        out[(att.name, item.name)] = world._pair(item.geometry, item.transform, att.geometry, transform, request)[0]
    for k, body in enumerate(world.bodies):
        if body.name not in att.touch:
            geometry, placement = world._body_geometry[k][0], world._body_transform(k)
            out[(att.name, body.name)] = world._pair(geometry, placement, att.geometry, transform, request)[0]
    return out


ATTACHED_SHAPES = {
    "box": Box((0.05, 0.04, 0.12)),
    "cylinder": Cylinder(0.03, 0.14),
    "capsule": Capsule(0.03, 0.1),
    "sphere": Sphere(0.05),
}


@pytest.mark.parametrize("shape", sorted(ATTACHED_SHAPES))
@pytest.mark.parametrize("bound_beyond", [np.inf, 0.05])
def test_attached_pairs_equal_one_by_one_queries(robot: taplan.Robot, bound_beyond: float, shape: str) -> None:
    """An attached object's pairs in the batch: against half-spaces in closed form (equal to coal to 1e-9 m at every
    configuration), against the robot's capsules and solid obstacles bounded by its containing capsule: lower
    bounds, equal to coal where within ``bound_beyond`` (spheres and capsules: everywhere); witness points the
    distance apart along the normal."""
    scene = _scene(1)
    scene.attach("tool", ATTACHED_SHAPES[shape], "right_tcp", ([0, 0, 0.06], [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    world._request.gjk_tolerance = world._request.epa_tolerance = 1e-12  # the pairs left to coal, as the reference
    Q = _configurations(robot, 16, 11)
    matrix = world.distance_matrix(Q, bound_beyond=bound_beyond)
    column = {pair: k for k, pair in enumerate(matrix.pairs)}
    halfspaces = {name for name, o in scene.obstacles.items() if isinstance(o.shape, HalfSpace)}
    bounded = penetrating = 0
    for n, q in enumerate(Q):
        reference = _attached_pairs_one_by_one(world, q)
        assert set(reference) == {pair for pair in matrix.pairs if pair[0] == "tool"}
        for pair, d in reference.items():
            got = matrix.distance[n, column[pair]]
            assert got <= d + DIST_TOL  # [m] a lower bound always
            if got <= bound_beyond or pair[1] in halfspaces or shape in ("capsule", "sphere"):
                assert got == pytest.approx(d, abs=DIST_TOL)  # [m] exact
            else:
                bounded += 1
            penetrating += d < 0.0
            k = column[pair]
            if got > 1e-6 and got == pytest.approx(d, abs=DIST_TOL):  # a clear exact pair: its witnesses
                gap = matrix.point_a[n, k] - matrix.point_b[n, k]
                np.testing.assert_allclose(gap, got * matrix.normal[n, k], rtol=0, atol=1e-9)  # [m]
    assert penetrating > 0  # the penetration depths were compared too
    assert bounded > 0 or not np.isfinite(bound_beyond) or shape in ("capsule", "sphere")  # the bounds were used


def test_segment_box_and_cylinder_against_dense_sampling() -> None:
    rng = np.random.default_rng(5)
    M = 200
    e0, e1 = rng.uniform(-0.5, 0.5, (M, 3)), rng.uniform(-0.5, 0.5, (M, 3))
    half = rng.uniform(0.02, 0.2, (M, 3))
    t = np.linspace(0.0, 1.0, 20001)
    points = e0[:, None] + t[None, :, None] * (e1 - e0)[:, None]
    s, near = segment_box(e0, e1, half)
    box_dense = np.linalg.norm(np.maximum(np.abs(points) - half[:, None], 0.0), axis=2).min(axis=1)
    box_exact = np.linalg.norm(e0 + s[:, None] * (e1 - e0) - near, axis=1)
    assert np.all(box_exact <= box_dense + 1e-12) and np.all(box_dense - box_exact < 1e-4)
    size = np.column_stack([half[:, 0], half[:, 0], half[:, 2]])
    s, near = segment_cylinder(e0, e1, size)
    radial = np.maximum(np.hypot(points[..., 0], points[..., 1]) - size[:, None, 0], 0.0)
    axial = np.maximum(np.abs(points[..., 2]) - size[:, None, 2], 0.0)
    cylinder_dense = np.hypot(radial, axial).min(axis=1)
    cylinder_exact = np.linalg.norm(e0 + s[:, None] * (e1 - e0) - near, axis=1)
    assert np.all(cylinder_exact <= cylinder_dense + 1e-10) and np.all(cylinder_dense - cylinder_exact < 1e-4)


def _full_scene(seed: int, attached: bool = True) -> Scene:
    """Every closed-form shape, perceived occupancy (voxels as boxes) and an attached object."""
    from taplan.scene.occupancy import Occupancy

    scene = _scene(seed)
    rng = np.random.default_rng(seed + 100)
    voxels = np.unique(rng.integers(0, 12, (60, 3)), axis=0)
    scene.add("seen", Occupancy(0.02, np.array([0.3, -0.15, -0.45]), voxels))
    if attached:
        scene.attach("tool", Cylinder(0.03, 0.12), "left_tcp", ([0, 0, 0.06], [0, 0, 0, 1]))
    return scene


@pytest.mark.parametrize(("seed", "native", "attached"), [(0, True, True), (1, True, False), (2, False, True)])
def test_single_queries_equal_the_coal_reference(robot: taplan.Robot, seed: int, native: bool, attached: bool) -> None:
    """CollisionWorld.distances (closed forms; end points from the compiled kernel, or pinocchio without one)
    against the coal reference (engine=False): the same pairs in the same order, distances to 1e-9 m, Jacobians
    where the witnesses are unique."""
    scene = _full_scene(seed, attached)
    world, reference = CollisionWorld(robot, scene), _reference(robot, scene)
    if not native:
        world._kernel = None  # as without a C compiler
    world._request.gjk_tolerance = world._request.epa_tolerance = 1e-12  # both use coal for the attached pairs
    cylinders = {"pole", "drum", "tool"}
    compared = penetrating = 0
    for q in _configurations(robot, 40, seed + 10):
        for cutoff, bound in ((np.inf, np.inf), (0.05, np.inf), (np.inf, 0.1), (np.inf, -np.inf)):
            got = world.distances(q, cutoff=cutoff, bound_beyond=bound)
            ref = reference.distances(q, cutoff=cutoff, bound_beyond=bound)
            assert got.pairs == ref.pairs
            np.testing.assert_allclose(got.travel, ref.travel, rtol=0, atol=1e-12)
            if bound < np.inf:  # bounds: their witnesses are nominal
                # the attached object's pairs: lower bounds (closed forms or bounding capsules, tighter than the
                # reference's spheres), exact where within the bound; the others as the reference reports them
                tool = np.array([pair[0] == "tool" for pair in ref.pairs], dtype=bool)
                np.testing.assert_allclose(got.distance[~tool], ref.distance[~tool], rtol=0, atol=DIST_TOL)
                full = reference.distances(q, jacobian=False)
                every = dict(zip(full.pairs, full.distance, strict=True))
                exact = np.array([every[pair] for pair in ref.pairs])[tool]
                assert np.all(got.distance[tool] <= exact + DIST_TOL)
                within = got.distance[tool] <= bound
                np.testing.assert_allclose(got.distance[tool][within], exact[within], rtol=0, atol=DIST_TOL)
                continue
            np.testing.assert_allclose(got.distance, ref.distance, rtol=0, atol=DIST_TOL)
            clear = ref.distance > 1e-6  # penetrating pairs: coal's EPA witnesses are not unique
            penetrating += int(np.sum(~clear))
            for k in np.flatnonzero(clear):
                tolerance = CYLINDER_JAC_TOL if set(ref.pairs[k]) & cylinders else JAC_TOL  # the tool is one too
                np.testing.assert_allclose(got.jacobian[k], ref.jacobian[k], rtol=0, atol=tolerance)
                np.testing.assert_allclose(got.normal[k], ref.normal[k], rtol=0, atol=1e-4)
                compared += 1
        (d, pair), (d_ref, pair_ref) = world.min_distance(q), reference.min_distance(q)
        assert d == pytest.approx(d_ref, abs=DIST_TOL) and (pair == pair_ref or d < -1e-6)
        d_all, pair_all = reference.distances(q, jacobian=False).closest()  # branch and bound = every pair exact
        assert d == pytest.approx(d_all, abs=DIST_TOL) and (pair == pair_all or d < -1e-6)
    assert penetrating > 0 and compared > 1000  # both regimes were exercised
    assert any(p[1] == "seen" for p in ref.pairs) and attached == any(p[0] == "tool" for p in ref.pairs)


def test_single_query_jacobian_matches_finite_differences(robot: taplan.Robot) -> None:
    scene = _full_scene(3)
    world = CollisionWorld(robot, scene)
    world._request.gjk_tolerance = world._request.epa_tolerance = 1e-12  # coal's 1e-6 m would swamp h = 1e-6 rad
    h = 1e-6
    rng = np.random.default_rng(6)
    for q in _configurations(robot, 8, 5):
        got = world.distances(q)
        dq = rng.normal(size=robot.nq)
        dq /= np.linalg.norm(dq)
        plus, minus = world.distances(q + h * dq), world.distances(q - h * dq)
        assert plus.pairs == got.pairs == minus.pairs
        numeric = (plus.distance - minus.distance) / (2 * h)
        smooth = got.distance > 1e-3  # away from contact the distance is differentiable
        np.testing.assert_allclose((got.jacobian @ dq)[smooth], numeric[smooth], rtol=0, atol=FD_TOL)


def test_worlds_sharing_the_compiled_kernel_across_threads(robot: taplan.Robot) -> None:
    """Worlds of one robot share the compiled end point kernel's buffers; two threads querying at once still get
    each configuration's own distances (the compiled call releases the GIL)."""
    import threading

    scene = _scene(4)
    worlds = [CollisionWorld(robot, scene), CollisionWorld(robot, scene)]
    Q = _configurations(robot, 30, 4)
    expected = [worlds[0].distances(q).distance for q in Q]
    failures: list[int] = []

    def run(world: CollisionWorld, order: np.ndarray) -> None:
        for _ in range(5):
            for k in order:
                if not np.array_equal(world.distances(Q[k]).distance, expected[k]):
                    failures.append(int(k))

    orders = (np.arange(30), np.arange(30)[::-1])
    threads = [threading.Thread(target=run, args=(w, o)) for w, o in zip(worlds, orders, strict=True)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not failures


@pytest.mark.parametrize(("seed", "bound_beyond"), [(0, np.inf), (1, 0.1), (2, 0.02)])
def test_distances_of_a_subset_equal_the_full_batch(robot: taplan.Robot, seed: int, bound_beyond: float) -> None:
    """Every shape, perceived occupancy and penetrating configurations: the subset's distances are the full batch's
    columns (the same closed forms, bounds and coal cases), in any order, repeated or not."""
    scene = _full_scene(seed, attached=False)
    world = CollisionWorld(robot, scene)
    engine = world.engine()
    Q = _configurations(robot, 25, seed)
    full = engine.evaluate(Q, jacobian=False, bound_beyond=bound_beyond)
    assert full.pairs == tuple(engine.pair_names)
    rng = np.random.default_rng(seed)
    columns = rng.choice(len(full.pairs), 120, replace=True)
    columns[:2] = [0, len(full.pairs) - 1]  # a robot pair and an occupancy pair (the last obstacle)
    got = engine.distances_of(Q, columns, bound_beyond=bound_beyond)
    field = np.array([full.pairs[k][1] == "seen" for k in columns])
    assert field.any() and (~field).any()
    np.testing.assert_allclose(got[:, ~field], full.distance[:, columns[~field]], rtol=0, atol=1e-12)
    assert np.any(full.distance[:, columns] < 0.0)  # penetrations (coal's EPA) were among them
    # the occupancy's far capsules get a lower bound from its voxel surface, which depends on the batch: a lower
    # bound of the exact distance, and the exact distance itself within bound_beyond
    exact = engine.evaluate(Q, jacobian=False).distance[:, columns[field]]
    assert np.all(got[:, field] <= exact + 1e-12)
    near = exact <= bound_beyond
    np.testing.assert_allclose(got[:, field][near], exact[near], rtol=0, atol=1e-9)
    names = tuple(full.pairs[k] for k in columns)
    named = world.pair_distances(Q, names, bound_beyond=bound_beyond)
    assert named is not None and named.pairs == names
    np.testing.assert_allclose(named.distance, got, rtol=0, atol=0)
    np.testing.assert_allclose(named.travel, full.travel[columns], rtol=0, atol=0)
    every = world.pair_distances(Q, bound_beyond=bound_beyond)  # every pair: the full batch's, distances only
    assert every is not None and every.pairs == full.pairs
    solid = np.array([pair[1] != "seen" for pair in full.pairs])
    np.testing.assert_allclose(every.distance[:, solid], full.distance[:, solid], rtol=0, atol=1e-12)


@pytest.mark.parametrize("bound_beyond", [np.inf, 0.05])
def test_pair_distances_with_attached_objects_equal_the_full_batch(robot: taplan.Robot, bound_beyond: float) -> None:
    """With an attached object, pair_distances answers any subset of the pairs, in the asked order, with the full
    batch's distances (bounds included) and travel rows; every pair when none are named."""
    scene = _scene(0)
    scene.attach("tool", Cylinder(0.03, 0.12), "left_tcp", ([0, 0, 0.06], [0, 0, 0, 1]))
    world = CollisionWorld(robot, scene)
    Q = _configurations(robot, 6, 3)
    matrix = world.distance_matrix(Q, bound_beyond=bound_beyond)
    column = {pair: k for k, pair in enumerate(matrix.pairs)}
    tools = [pair for pair in matrix.pairs if pair[0] == "tool"]
    for asked in ((matrix.pairs[0],), (tools[3], matrix.pairs[5], tools[0]), tuple(tools), None):
        got = world.pair_distances(Q, asked, bound_beyond=bound_beyond)
        assert got is not None
        assert set(got.pairs) == set(matrix.pairs) if asked is None else got.pairs == asked
        k = [column[pair] for pair in got.pairs]
        np.testing.assert_allclose(got.distance, matrix.distance[:, k], rtol=0, atol=1e-12)  # [m]
        np.testing.assert_array_equal(got.travel, matrix.travel[k])
    assert world.pair_distances(Q, (("tool", "no such body"),)) is None
    assert CollisionWorld(robot, scene, engine=False).pair_distances(Q, (matrix.pairs[0],)) is None


def test_worlds_with_the_same_bodies_share_one_kernel_and_other_bodies_get_their_own(robot: taplan.Robot) -> None:
    from taplan.scene.engine import _native_kernel

    first = _native_kernel(CollisionWorld(robot, _scene(0)))
    if first is None:
        pytest.skip("no C compiler: the numpy path has no kernel to share")
    assert _native_kernel(CollisionWorld(robot)) is first  # obstacles are not part of the kernel
    world = CollisionWorld(robot, gripper="closed")  # other finger bodies: another chain
    assert _native_kernel(world) is not first
    Q = _configurations(robot, 3, 11)
    ends, _rows = DistanceEngine(world).segments(Q)
    fallback = _Kinematics.__new__(_Kinematics)
    fallback.world, fallback.model, fallback.nv, fallback.B = world, world.model, world.model.nv, len(world.bodies)
    ends_ref, _ = fallback._pinocchio(Q, True)
    np.testing.assert_allclose(ends, ends_ref, rtol=0, atol=1e-12)  # [m]: the closed fingers' own end points


def test_the_compiler_lookup_follows_cc_and_path(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from taplan.ik import _native

    monkeypatch.setenv("PATH", str(tmp_path))  # an empty directory: no compiler at all
    monkeypatch.delenv("CC", raising=False)
    assert _native._compiler() is None and not _native.native_enabled()
    fake = tmp_path / "mycc"
    fake.write_text("#!/bin/sh\n")
    fake.chmod(0o755)
    monkeypatch.setenv("CC", "mycc")
    assert _native._compiler() == "mycc"


@pytest.fixture(scope="module")
def family_worlds(robot: taplan.Robot) -> list[tuple[CollisionWorld, np.ndarray]]:
    """One world of each benchmark family (problems(26, 0): two of each; the first of each kept) with its
    problem's start and goal and random configurations (many penetrate the obstacles)."""
    from benchmarks._scenes import problems

    seen: dict[str, tuple[CollisionWorld, np.ndarray]] = {}
    for k, problem in enumerate(problems(26, 0)):
        if problem.family in seen:
            continue
        ends = np.vstack([problem.start, problem.goal_q])
        Q = np.vstack([ends, _configurations(robot, 24, 100 + k)])
        seen[problem.family] = (CollisionWorld(robot, problem.scene), Q)
    return list(seen.values())


def test_compiled_pairs_equal_the_numpy_engine_on_every_benchmark_family(
    robot: taplan.Robot, family_worlds: list[tuple[CollisionWorld, np.ndarray]]
) -> None:
    """The compiled loops (taplan.scene.engine_kernels) against the numpy engine they replaced
    (tests/engine_reference.py), over every benchmark family's scene: the same pairs; distances, witness points,
    normals and Jacobian rows to 1e-9 (bit for bit where numpy's BLAS adds as the kernels do); with and without
    bounds, Jacobian cutoffs and obstacles; coal's penetration depths included; distances_of too."""
    from engine_reference import NumpyEngine

    settings = (
        {},
        {"bound_beyond": 0.05, "jacobian_within": 0.05},
        {"jacobian": False, "bound_beyond": 0.1},
        {"obstacles": False},
        {"bound_beyond": -np.inf, "jacobian_within": 0.0},
    )
    penetrating = 0
    for world, Q in family_worlds:
        engine, reference = world.engine(), NumpyEngine(world)
        for kwargs in settings:
            got, want = engine.evaluate(Q, **kwargs), reference.evaluate(Q, **kwargs)
            assert got.pairs == want.pairs
            np.testing.assert_allclose(got.distance, want.distance, rtol=0, atol=DIST_TOL)
            for name in ("point_a", "point_b", "normal"):
                np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=0, atol=DIST_TOL)
            if want.jacobian is None:
                assert got.jacobian is None
            else:
                np.testing.assert_allclose(got.jacobian, want.jacobian, rtol=0, atol=JAC_TOL)
            penetrating += int((want.distance < 0).sum())
        columns = np.arange(len(engine.pair_columns()[0]))
        for beyond in (np.inf, 0.05):
            got_d = engine.distances_of(Q, columns, bound_beyond=beyond)
            np.testing.assert_allclose(got_d, reference.distances_of(Q, columns, bound_beyond=beyond), atol=DIST_TOL)
            # the same numbers as the batch's own
            np.testing.assert_array_equal(got_d, engine.evaluate(Q, jacobian=False, bound_beyond=beyond).distance)
    assert penetrating > 100


def test_compiled_pairs_equal_the_numpy_engine_with_pinocchio_kinematics(
    robot: taplan.Robot, family_worlds: list[tuple[CollisionWorld, np.ndarray]]
) -> None:
    """Without the compiled kinematics (no C compiler) the end points' Jacobians come from pinocchio in another
    memory layout: the compiled pairs still equal the numpy engine's."""
    from engine_reference import NumpyEngine

    world, Q = family_worlds[4]  # clutter: many boxes
    engine, reference = world.engine(), NumpyEngine(world)
    engine._kinematics.native = reference._kinematics.native = None
    got, want = engine.evaluate(Q), reference.evaluate(Q)
    for name in ("distance", "point_a", "point_b", "normal"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=0, atol=DIST_TOL)
    np.testing.assert_allclose(got.jacobian, want.jacobian, rtol=0, atol=JAC_TOL)


def test_penetrating_axes_go_to_coal_in_both_engines(
    robot: taplan.Robot, family_worlds: list[tuple[CollisionWorld, np.ndarray]]
) -> None:
    """The pairs whose axis enters a box or cylinder are coal's in the compiled engine as in the numpy one: the same
    queries, and their witness points and Jacobian rows are coal's."""
    from engine_reference import NumpyEngine

    asked: dict[str, list[tuple[int, int]]] = {"compiled": [], "numpy": []}
    for world, Q in family_worlds:
        for name, engine in (("compiled", world.engine()), ("numpy", NumpyEngine(world))):
            coal = engine._coal

            def counted(ends: np.ndarray, body: int, item: int, name: str = name, coal: object = coal) -> object:
                asked[name].append((body, item))
                return coal(ends, body, item)  # type: ignore[operator]

            engine._coal = counted  # type: ignore[method-assign]
            engine.evaluate(Q)
    assert len(asked["compiled"]) > 20
    assert sorted(asked["compiled"]) == sorted(asked["numpy"])
