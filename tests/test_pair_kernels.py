"""taplan.scene.pair_kernels: the compiled scalar closed forms equal the engine's numpy functions (segment_parameters,
segment_box, segment_cylinder, the core segment, the half-space, solid_pairs) to 1e-12 on random and degenerate
inputs: zero-length and parallel segments, segments touching or entering boxes, cylinders' caps and rims."""

from __future__ import annotations

import numpy as np
import pytest
from engine_reference import _point_segment

from taplan.scene import engine
from taplan.scene import pair_kernels as kernels

TOL = 1e-12  # [m] (and parameters): the same arithmetic, so rounding at most


def _rows(x: np.ndarray) -> list[tuple[float, ...]]:
    return [tuple(float(v) for v in row) for row in x]


def _segments(seed: int, M: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Random segments around the origin, and the degenerate kinds in their midst: zero length, axis-aligned
    (directions with zero components), end points on the unit planes."""
    rng = np.random.default_rng(seed)
    e0, e1 = rng.uniform(-0.5, 0.5, (M, 3)), rng.uniform(-0.5, 0.5, (M, 3))
    e1[:40] = e0[:40]  # points
    e1[40:80, :2] = e0[40:80, :2]  # along z
    e1[80:120, 1:] = e0[80:120, 1:]  # along x
    e1[120:160, 2] = e0[120:160, 2]  # in a z plane
    e0[160:200] = np.round(e0[160:200], 1)  # on grid planes (face planes of the sizes below)
    e1[160:200] = np.round(e1[160:200], 1)
    return e0, e1


def _pair_segments(seed: int, M: int = 400) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    p0, p1 = _segments(seed, M)
    q0, q1 = rng.uniform(-0.5, 0.5, (M, 3)), rng.uniform(-0.5, 0.5, (M, 3))
    q1[200:240] = q0[200:240]  # a point against a segment
    q0[240:280], q1[240:280] = p0[240:280] + 0.1, p1[240:280] + 0.1  # parallel
    q0[280:300], q1[280:300] = (
        p0[280:300] + 0.3 * (p1 - p0)[280:300],
        p1[280:300] + 0.5 * (p1 - p0)[280:300],
    )  # collinear
    q0[300:320], q1[300:320] = p1[300:320], q1[300:320]  # sharing an end point
    q0[320:340], q1[320:340] = p0[320:340], p0[320:340]  # a point on the other's end
    q0[340:360], q1[340:360] = p1[340:360], p0[340:360]  # the same segment reversed
    return p0, p1, q0, q1


@pytest.mark.parametrize("seed", [0, 1])
def test_segment_segment_equals_segment_parameters(seed: int) -> None:
    p0, p1, q0, q1 = _pair_segments(seed)
    s, t = engine.segment_parameters(p0, p1, q0, q1)
    got = np.array([kernels.segment_segment(*row) for row in zip(*map(_rows, (p0, p1, q0, q1)), strict=True)])
    np.testing.assert_allclose(got[:, 0], s, rtol=0, atol=TOL)
    np.testing.assert_allclose(got[:, 1], t, rtol=0, atol=TOL)


def test_point_segment_equals_the_broad_phase() -> None:
    e0, e1 = _segments(2)
    point = np.array([0.05, -0.1, 0.02])
    want = _point_segment(point, e0, e1)
    got = [kernels.point_segment(tuple(point.tolist()), a, b) for a, b in zip(_rows(e0), _rows(e1), strict=True)]
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL)


def _unpack(results: list) -> tuple[np.ndarray, np.ndarray]:
    return np.array([r[0] for r in results]), np.array([r[1] for r in results])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_segment_box_equals_the_numpy_pieces(seed: int) -> None:
    e0, e1 = _segments(seed)
    rng = np.random.default_rng(seed + 10)
    half = rng.uniform(0.02, 0.3, (len(e0), 3))
    half[160:200] = 0.1 * rng.integers(1, 4, (40, 3))  # the grid points and segments touch faces, edges, corners
    half[200:240] = np.abs(e0[200:240]) + 0.05  # the first end point inside: the axis enters the box
    s, near = engine.segment_box(e0, e1, half)
    got_s, got_near = _unpack([kernels.segment_box(*row) for row in zip(*map(_rows, (e0, e1, half)), strict=True)])
    np.testing.assert_allclose(got_s, s, rtol=0, atol=TOL)
    np.testing.assert_allclose(got_near, near, rtol=0, atol=TOL)
    inside = np.all(np.abs(e0[200:240]) < half[200:240], axis=1)
    assert inside.all()  # the entering segments were compared


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_segment_cylinder_equals_the_numpy_closed_form_and_search(seed: int) -> None:
    e0, e1 = _segments(seed)
    rng = np.random.default_rng(seed + 20)
    M = len(e0)
    radius, half_length = rng.uniform(0.02, 0.3, M), rng.uniform(0.0, 0.3, M)
    radius[160:200], half_length[160:200] = 0.1, 0.2  # grid points on the cap planes and the rim
    # segments across a rim: from beside the lateral surface to above the cap
    angle = rng.uniform(0, 2 * np.pi, 40)
    e0[240:280] = np.column_stack(
        [1.5 * radius[240:280] * np.cos(angle), 1.5 * radius[240:280] * np.sin(angle), 0 * angle]
    )
    e1[240:280] = np.column_stack([0.5 * radius[240:280] * np.cos(angle), 0 * angle, half_length[240:280] + 0.05])
    size = np.column_stack([radius, radius, half_length])
    s, near = engine.segment_cylinder(e0, e1, size)
    rows = zip(_rows(e0), _rows(e1), radius.tolist(), half_length.tolist(), strict=True)
    got_s, got_near = _unpack([kernels.segment_cylinder(*row) for row in rows])
    np.testing.assert_allclose(got_s, s, rtol=0, atol=TOL)
    np.testing.assert_allclose(got_near, near, rtol=0, atol=TOL)
    # both branches were compared: the lateral closed form and the search
    capsule_s, on_axis = engine._segment_capsule(e0, e1, size)
    t_axis = (on_axis[:, 2] + half_length) / np.maximum(2 * half_length, 1e-18)
    lateral = (t_axis > 1e-9) & (t_axis < 1 - 1e-9)
    assert 50 < lateral.sum() < M - 50


@pytest.mark.parametrize("seed", [0, 1])
def test_segment_core_and_halfspace_equal_the_numpy_forms(seed: int) -> None:
    e0, e1 = _segments(seed)
    rng = np.random.default_rng(seed + 30)
    half_length = rng.uniform(0.0, 0.3, len(e0))
    half_length[:100] = 0.0  # spheres
    size = np.column_stack([0 * half_length, 0 * half_length, half_length])
    s, near = engine._segment_capsule(e0, e1, size)
    got_s, got_near = _unpack(
        [kernels.segment_core(a, b, h) for a, b, h in zip(_rows(e0), _rows(e1), half_length.tolist(), strict=True)]
    )
    np.testing.assert_allclose(got_s, s, rtol=0, atol=TOL)
    np.testing.assert_allclose(got_near, near, rtol=0, atol=TOL)
    s, near = engine._segment_halfspace(e0, e1, size)
    got_s, got_near = _unpack([kernels.segment_halfspace(a, b) for a, b in zip(_rows(e0), _rows(e1), strict=True)])
    np.testing.assert_allclose(got_s, s, rtol=0, atol=TOL)
    np.testing.assert_allclose(got_near, near, rtol=0, atol=TOL)


def test_cylinder_nearest_inside_beside_and_beyond() -> None:
    rng = np.random.default_rng(4)
    points = rng.uniform(-0.4, 0.4, (300, 3))
    points[:20, :2] = 0.0  # on the axis
    want = engine._cylinder_nearest(points, np.full(300, 0.2), np.full(300, 0.15))
    got = np.array([kernels.cylinder_nearest(p, 0.2, 0.15) for p in _rows(points)])
    np.testing.assert_allclose(got, want, rtol=0, atol=TOL)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_capsule_solid_equals_solid_pairs(seed: int) -> None:
    """Every solid kind with its robot radius: parameter, signed distance, witnesses, normal and the pairs left to
    coal; many rows penetrate (the axis inside boxes and cylinders)."""
    e0, e1 = _segments(seed)
    rng = np.random.default_rng(seed + 40)
    M = len(e0)
    kind = rng.integers(0, 4, M)
    size = rng.uniform(0.02, 0.3, (M, 3))
    size[kind == kernels.CYLINDER, 1] = size[kind == kernels.CYLINDER, 0]
    rounded = (kind == kernels.SPHERE) | (kind == kernels.CAPSULE)
    size[rounded, :2] = 0.0
    size[kind == kernels.SPHERE, 2] = 0.0
    core = np.where(rounded, rng.uniform(0.01, 0.1, M), 0.0)
    radius = rng.uniform(0.01, 0.08, M)
    want = engine.solid_pairs(kind, size, core, e0, e1, radius)
    rows = zip(kind.tolist(), _rows(size), core.tolist(), _rows(e0), _rows(e1), radius.tolist(), strict=True)
    got = [kernels.capsule_solid(*row) for row in rows]
    for k in range(5):
        np.testing.assert_allclose(np.array([g[k] for g in got]), want[k], rtol=0, atol=TOL)
    inside = np.array([g[5] for g in got])
    np.testing.assert_array_equal(inside, want[5])
    assert inside.sum() > 10 and (want[1] < 0).sum() > inside.sum()  # penetrations both kinds: coal's and exact


def test_capsule_solid_halfspace_is_the_lower_end() -> None:
    e0, e1 = _segments(3)
    radius = 0.05
    got = [
        kernels.capsule_solid(kernels.HALF_SPACE, (0.0, 0.0, 0.0), 0.0, a, b, radius)
        for a, b in zip(_rows(e0), _rows(e1), strict=True)
    ]
    lower = np.minimum(e0[:, 2], e1[:, 2])
    np.testing.assert_allclose([g[1] for g in got], lower - radius, rtol=0, atol=TOL)
    np.testing.assert_allclose([g[4] for g in got], np.tile([0.0, 0.0, 1.0], (len(e0), 1)), rtol=0, atol=0)
    pa = np.array([g[2] for g in got])
    np.testing.assert_allclose(pa[:, 2], lower - radius, rtol=0, atol=TOL)
    assert not any(g[5] for g in got)


def test_shape_codes_are_the_engines() -> None:
    from taplan.scene import Box, Capsule, Cylinder, HalfSpace, Sphere

    assert engine.shape_code(Box((0.1, 0.1, 0.1))) == kernels.BOX
    assert engine.shape_code(Sphere(0.1)) == kernels.SPHERE
    assert engine.shape_code(Capsule(0.1, 0.2)) == kernels.CAPSULE
    assert engine.shape_code(Cylinder(0.1, 0.2)) == kernels.CYLINDER
    assert engine.shape_code(HalfSpace()) == kernels.HALF_SPACE
    assert (kernels.SEARCH_POINTS, kernels.SEARCH_ROUNDS) == (engine.SEARCH_POINTS, engine.SEARCH_ROUNDS)
