"""Depth images rendered from a scene's primitives by ray casting: ground truth for perception tests, and the
simulator's synthetic wrist-camera images.

Each pixel's ray ``o + t R (x, y, 1)`` meets the shapes in closed form (boxes by slabs, spheres, capsules and
cylinders by their quadrics, half-spaces by their plane); with the ray's camera z equal to 1, ``t`` is the pixel's
z-depth. The robot's own bodies can be drawn too (capsules), so self-filtering is tested on what a wrist camera
really sees. Noise (Gaussian, metres) and missing pixels (NaN) are optional and seeded.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from taplan.errors import InvalidInputError
from taplan.scene.camera import PinholeCamera
from taplan.scene.scene import Scene
from taplan.scene.shapes import Box, Capsule, Cylinder, HalfSpace, Sphere

__all__ = ["render_depth", "depth_to_16uc1"]


def _ray_box(o: np.ndarray, d: np.ndarray, half: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-half - o) / d, (half - o) / d
    # fmax/fmin skip the NaN of a ray lying in a face plane
    near = np.fmax.reduce(np.fmin(t1, t2), axis=1)
    far = np.fmin.reduce(np.fmax(t1, t2), axis=1)
    return np.where((near <= far) & (near > 0), near, np.inf)


def _quadratic_first(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Smallest positive root of ``a t² + 2 b t + c`` per row (inf when none)."""
    disc = b * b - a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        root = np.sqrt(np.maximum(disc, 0.0))
        t = (-b - root) / a
    return np.where((disc >= 0) & (a > 1e-18) & (t > 0), t, np.inf)


def _ray_sphere(o: np.ndarray, d: np.ndarray, centre: np.ndarray, r: float) -> np.ndarray:
    w = o - centre
    return _quadratic_first(
        np.einsum("nk,nk->n", d, d), np.einsum("nk,nk->n", d, w), np.einsum("nk,nk->n", w, w) - r * r
    )


def _ray_tube(o: np.ndarray, d: np.ndarray, r: float, half_length: float) -> np.ndarray:
    """The side of the cylinder of radius r about z, |z| <= half_length (shape frame)."""
    a = d[:, 0] ** 2 + d[:, 1] ** 2
    b = o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1]
    c = o[:, 0] ** 2 + o[:, 1] ** 2 - r * r
    t = _quadratic_first(a, b, c)
    z = o[:, 2] + np.where(np.isfinite(t), t, 0.0) * d[:, 2]
    return np.where(np.abs(z) <= half_length, t, np.inf)


def _ray_capsule(o: np.ndarray, d: np.ndarray, r: float, length: float) -> np.ndarray:
    tube = _ray_tube(o, d, r, length / 2)
    ends = [_ray_sphere(o, d, np.array([0.0, 0.0, s * length / 2]), r) for s in (-1, 1)]
    return np.minimum(tube, np.minimum(*ends))


def _ray_cylinder(o: np.ndarray, d: np.ndarray, r: float, length: float) -> np.ndarray:
    best = _ray_tube(o, d, r, length / 2)
    for s in (-1.0, 1.0):
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (s * length / 2 - o[:, 2]) / d[:, 2]
        p = o + np.where(np.isfinite(t), t, 0.0)[:, None] * d
        hit = np.isfinite(t) & (t > 0) & (p[:, 0] ** 2 + p[:, 1] ** 2 <= r * r)
        best = np.minimum(best, np.where(hit, t, np.inf))
    return best


def _ray_halfspace(o: np.ndarray, d: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -o[:, 2] / d[:, 2]
    return np.where((o[:, 2] > 0) & (d[:, 2] < 0), t, np.inf)


def _ray_shape(shape: Any, o: np.ndarray, d: np.ndarray, name: str) -> np.ndarray:
    if isinstance(shape, Box):
        return _ray_box(o, d, np.asarray(shape.size) / 2)
    if isinstance(shape, Sphere):
        return _ray_sphere(o, d, np.zeros(3), shape.radius)
    if isinstance(shape, Capsule):
        return _ray_capsule(o, d, shape.radius, shape.length)
    if isinstance(shape, Cylinder):
        return _ray_cylinder(o, d, shape.radius, shape.length)
    if isinstance(shape, HalfSpace):
        return _ray_halfspace(o, d)
    raise InvalidInputError(f"{name}.shape", shape.kind, "a box, sphere, capsule, cylinder or half-space to render")


def _cone(rays: np.ndarray, lengths: np.ndarray, eye: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """Indices of the rays that may meet a sphere (inside the cone from ``eye`` around it): the only pixels a
    bounded shape needs to be intersected with."""
    offset = centre - eye
    distance = float(np.linalg.norm(offset))
    if not np.isfinite(radius) or distance <= radius:
        return np.arange(len(rays))
    cosine = (rays @ offset) / (lengths * distance)
    return np.flatnonzero(cosine >= math.sqrt(max(0.0, 1.0 - (radius / distance) ** 2)) - 1e-9)


def _segment_frame(start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, float]:
    """A frame at the segment's middle with z along it, and its length (cross products written out: np.cross
    costs more than the rest of a small capsule's rendering)."""
    axis = end - start
    length = math.sqrt(float(axis @ axis))
    z = axis / length if length > 1e-9 else np.array([0.0, 0.0, 1.0])
    if abs(z[0]) < 0.9:  # x = e_x × z
        x = np.array([0.0, -z[2], z[1]])
    else:  # x = e_y × z
        x = np.array([z[2], 0.0, -z[0]])
    x /= math.sqrt(float(x @ x))
    y = np.array([z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0]])
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, (start + end) / 2
    return T, length


def render_depth(
    camera: PinholeCamera,
    T_root_camera: np.ndarray,
    scene: Scene | None = None,
    *,
    capsules: Iterable[tuple[np.ndarray, np.ndarray, float]] = (),
    max_range: float = 4.0,
    noise: float = 0.0,
    missing: float = 0.0,
    rng: np.random.Generator | int | None = None,
) -> np.ndarray:
    """The z-depth image [m] (float32, NaN where nothing is hit within ``max_range`` or the pixel is missing) of a
    scene's obstacles (and of ``capsules`` given as ``(start, end, radius)`` in the root frame, e.g. the robot's
    bodies) seen from ``T_root_camera`` (optical frame). Each bounded shape is intersected only with the pixels
    inside the cone around its bounding sphere.

    Args:
        noise: Standard deviation of Gaussian depth noise [m].
        missing: Fraction of pixels dropped at random (set NaN).
        rng: Seed or generator for noise and missing pixels.
    """
    if not (0.0 <= missing < 1.0) or not (noise >= 0.0 and math.isfinite(noise)):
        raise InvalidInputError("noise/missing", (noise, missing), "noise >= 0 [m] and missing in [0, 1)")
    R, t = T_root_camera[:3, :3], T_root_camera[:3, 3]
    rays = camera.rays().reshape(-1, 3).astype(float) @ R.T  # root-frame directions with camera z = 1
    lengths = np.linalg.norm(rays, axis=1)
    depth = np.full(len(rays), np.inf)

    def hit(shape: Any, T_root_shape: np.ndarray, radius: float, name: str) -> None:
        rows = _cone(rays, lengths, t, T_root_shape[:3, 3], radius)
        if not len(rows):
            return
        Rs, ts = T_root_shape[:3, :3], T_root_shape[:3, 3]
        o = np.broadcast_to((t - ts) @ Rs, (len(rows), 3))
        depth[rows] = np.minimum(depth[rows], _ray_shape(shape, o, rays[rows] @ Rs, name))

    for obstacle in scene.obstacles.values() if scene is not None else ():
        if obstacle.shape.kind == "occupancy":
            continue
        hit(obstacle.shape, obstacle.pose, obstacle.shape.bounding_radius(), obstacle.name)
    for start, end, radius in capsules:
        start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
        T, length = _segment_frame(start, end)
        shape = Capsule(float(radius), length) if length > 1e-9 else Sphere(float(radius))
        hit(shape, T, float(radius) + length / 2, "capsule")
    depth[depth > max_range] = np.inf
    generator = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    if noise > 0:
        depth = depth + generator.normal(0.0, noise, depth.shape)
    if missing > 0:
        depth[generator.random(depth.shape) < missing] = np.inf
    depth[~np.isfinite(depth)] = np.nan
    return depth.reshape(camera.height, camera.width).astype(np.float32)


def depth_to_16uc1(depth: np.ndarray) -> np.ndarray:
    """A metres image as ``16UC1`` millimetres (0 where NaN; depths beyond 65.535 m are 0 too)."""
    mm = np.round(np.nan_to_num(depth, nan=0.0) * 1000.0)
    return np.where((mm > 0) & (mm < 65536), mm, 0).astype(np.uint16)
