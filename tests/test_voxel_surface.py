"""Occupancy distances through the voxels' surface (taplan.scene.voxel_surface) and the sampler's occupancy test
(taplan.planning.field_check): exact where asked, lower bounds elsewhere, never "clear" where a body is closer."""

from __future__ import annotations

import numpy as np
import pytest

import taplan
from taplan.planning.compiled_check import ClearanceCheck
from taplan.planning.field_check import FieldClearance
from taplan.scene import Box, CollisionWorld, Scene
from taplan.scene.occupancy import Occupancy, segment_box_distance
from taplan.scene.voxel_surface import HALF_DIAGONAL, VoxelSurface


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _solids(rng: np.random.Generator) -> np.ndarray:
    """Voxel indices of a few solid blocks and scattered single voxels (the blocks have interior voxels)."""
    parts = [np.unique(rng.integers(0, 40, (300, 3)), axis=0)]
    for _ in range(4):
        lo = rng.integers(0, 30, 3)
        size = rng.integers(3, 10, 3)
        axes = [np.arange(lo[k], lo[k] + size[k]) for k in range(3)]
        parts.append(np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3))
    return np.unique(np.concatenate(parts), axis=0)


def _brute(occupancy: Occupancy, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Each segment's exact distance [m] to the union of every voxel box."""
    lo, hi = occupancy.boxes()
    out = np.empty(len(starts))
    for c in range(len(starts)):
        gap, _, _ = segment_box_distance(
            np.repeat(starts[c : c + 1], len(lo), 0), np.repeat(ends[c : c + 1], len(lo), 0), lo, hi
        )
        out[c] = gap.min()
    return out


def test_surface_voxels_are_the_occupied_ones_with_a_free_face_neighbour() -> None:
    voxels = np.stack(np.meshgrid(*[np.arange(5)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)  # a 5^3 cube
    surface = VoxelSurface(0.01, np.zeros(3), voxels)
    assert len(surface) == 5**3 - 3**3  # the 3^3 core has no free face neighbour
    assert surface.inside(np.array([[0.025, 0.025, 0.025], [0.055, 0.0, 0.0], [-0.001, 0.01, 0.01]])).tolist() == [
        True,
        False,
        False,
    ]


def test_capsule_distances_equal_every_box_and_bounds_stay_below() -> None:
    rng = np.random.default_rng(4)
    occupancy = Occupancy(0.02, np.array([-0.4, -0.4, -0.4]), _solids(rng))
    C = 300
    starts = rng.uniform(-0.55, 0.55, (C, 3))
    ends = starts + rng.normal(0, 0.12, (C, 3))
    ends[:20] = starts[:20]  # spheres
    radii = rng.uniform(0.0, 0.06, C)
    exact = _brute(occupancy, starts, ends) - radii
    d, pa, pb, n = occupancy.capsule_distances(starts, ends, radii)
    inside = exact <= -radii + 1e-12  # the axis meets a voxel: reported as -radius
    assert np.all(np.abs(d - exact) < 1e-12)
    assert inside.sum() > 10 and (exact > 0.1).sum() > 10  # both far and colliding capsules were asked
    apart = d > 1e-9
    assert np.allclose(np.linalg.norm(pa[apart] - pb[apart], axis=1), d[apart], atol=1e-9)
    assert np.allclose(pa[apart] - pb[apart], d[apart, None] * n[apart], atol=1e-9)
    for limit in (-np.inf, 0.0, 0.01, 0.05, 0.1, 0.3):
        for kwargs in ({"cutoff": limit}, {"bound_beyond": limit}):
            bounded = occupancy.capsule_distances(starts, ends, radii, **kwargs)[0]
            assert np.all(bounded <= exact + 1e-12)  # a lower bound everywhere
            assert np.all((np.abs(bounded - exact) < 1e-12) | (exact > limit))  # exact within the limit
            if "cutoff" in kwargs:
                assert np.all((bounded <= limit) == (exact <= limit))
        if limit >= 0:  # the sampler's yes/no question: exactly "is the distance at least the clearance?"
            assert np.array_equal(occupancy.capsules_clear(starts, ends, radii, limit), exact >= limit)


def test_the_coarse_field_bounds_every_point_from_below() -> None:
    rng = np.random.default_rng(5)
    occupancy = Occupancy(0.01, np.array([0.1, -0.2, -0.3]), _solids(rng))
    surface = occupancy._surface
    points = rng.uniform(-0.2, 0.7, (400, 3))
    lo, hi = occupancy.boxes()
    true = np.array([np.linalg.norm(p - np.clip(p, lo, hi), axis=1).min() for p in points])
    outside = ~surface.inside(points)
    assert np.all(surface.coarse(points)[outside] <= true[outside] + 1e-9)
    # and the k-d tree's: the nearest surface centre is within half a voxel diagonal of the nearest box
    centre = surface.tree.query(points[outside])[0]
    assert np.all(centre - 0.01 * HALF_DIAGONAL <= true[outside] + 1e-9)
    assert np.all(centre >= true[outside] - 1e-9)


def _perceived_like(robot: taplan.Robot) -> Scene:
    """A table of 1 cm voxels, a solid unknown block beside it, and a closed-form box: what a perceived scene holds."""
    h = 0.01
    xs, ys = np.meshgrid(np.arange(0.25, 0.85, h), np.arange(-0.6, 0.6, h), indexing="ij")
    table = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, -0.42)], axis=1)
    origin = np.array([-0.6, -1.2, -1.0])
    seen = np.unique(np.floor((table - origin) / h).astype(np.int64), axis=0)
    block = np.stack(
        np.meshgrid(np.arange(110, 130), np.arange(60, 100), np.arange(60, 75), indexing="ij"), axis=-1
    ).reshape(-1, 3)
    scene = Scene()
    scene.add("perceived", Occupancy(h, origin, seen))
    scene.add("perceived_unknown", Occupancy(h, origin, block))
    scene.add("post", Box((0.05, 0.05, 0.4)), ([0.45, 0.35, -0.2], [0, 0, 0, 1]))
    return scene


def test_field_clearance_agrees_with_the_world_at_many_configurations(robot: taplan.Robot) -> None:
    world = CollisionWorld(robot, _perceived_like(robot))
    rng = np.random.default_rng(6)
    limits = robot.planning_limits
    Q = limits.lower + rng.uniform(0.05, 0.95, (400, robot.nq)) * (limits.upper - limits.lower)
    fields = {"perceived", "perceived_unknown"}
    for clearance in (0.0, 0.02, 0.05):
        test = FieldClearance(world, clearance)
        got = test.many(Q)
        nearest = np.array(
            [
                min((d for (a, b), d in zip(x.pairs, x.distance, strict=True) if b in fields), default=np.inf)
                for x in (world.distances(q, jacobian=False) for q in Q)
            ]
        )
        assert np.array_equal(got, nearest >= clearance)  # never "clear" below the clearance, exact otherwise
        assert 20 < got.sum() < len(Q) - 20  # both answers occur
        assert all(test(q) == g for q, g in zip(Q[:20], got[:20], strict=True))


def test_sampler_check_covers_occupancy_and_matches_the_world(robot: taplan.Robot) -> None:
    world = CollisionWorld(robot, _perceived_like(robot))
    check = ClearanceCheck(world, 0.02)
    assert check.ready and check.fields is not None  # compiled pairs + the occupancy test
    rng = np.random.default_rng(7)
    limits = robot.planning_limits
    Q = limits.lower + rng.uniform(0.05, 0.95, (300, robot.nq)) * (limits.upper - limits.lower)
    got = np.array([check(q) for q in Q])
    truth = np.array([not world.in_collision(q, margin=0.02) for q in Q])
    assert np.array_equal(got, truth)
    assert 20 < got.sum() < len(Q) - 20
    # edges: the end alone, then the other states in one batch; the same answer as every state tested alone
    free = Q[truth]
    outcomes = []
    for a, b in zip(free[:-1:2], free[1::2], strict=False):
        b = a + 0.3 * (b - a)
        count = max(1, int(np.ceil(float(check.reach @ np.abs(b - a)) / 0.03)))
        states = a + np.arange(1, count + 1)[:, None] / count * (b - a)
        expected = all(not world.in_collision(s, margin=0.02) for s in states)
        assert check.motion(a, b, 0.03) == expected
        outcomes.append(expected)
    assert 3 <= sum(outcomes) <= len(outcomes) - 3  # both answers occur
