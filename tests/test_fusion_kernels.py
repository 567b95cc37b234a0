"""Fusion's compiled kernels (taplan.scene.fusion_kernels) leave exactly the voxel states the numpy code they
replaced left: ``NumpyGrid`` below is that code (OccupancyGrid's insert_image, mark_seen_free and near_segments as
of main 8e912cf, plus the "viewed into nothing" rule added with the kernels), run beside the compiled grid on the
same rendered images (robot in view, noise, missing pixels, thick surfaces, stamps)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import taplan
from benchmarks._scenes import make_scene
from taplan.scene.camera import PinholeCamera
from taplan.scene.occupancy import OccupancyGrid, _nearest_around
from taplan.scene.perception import Perception
from taplan.scene.raycast import render_depth

CAMERA = PinholeCamera(320, 240, 168.5, 168.5, 160.0, 120.0)  # the wrist camera's field of view at half size


class NumpyGrid(OccupancyGrid):
    """The grid with the numpy implementations the kernels replaced (the reference)."""

    def insert_image(
        self,
        depth: np.ndarray,
        ray_x: np.ndarray,
        ray_y: np.ndarray,
        T_root_camera: np.ndarray,
        stamp: float = 0.0,
        *,
        exclude: np.ndarray | None = None,
        thickness: float = 0.0,
    ) -> tuple[int, int]:
        """Mark the voxels a depth image (metres, NaN = no measurement) hits: pixel ``(row, col)`` is the point
        ``depth * (ray_x[col], ray_y[row], 1)`` of the camera at ``T_root_camera``. Separable rays make each root
        coordinate one multiply-add over the image, without forming the (N, 3) points. With ``thickness`` [m] the
        points up to that depth behind each hit are occupied too (every half voxel): surfaces are taken as solids
        at least that thick. Returns (measured, kept) pixels; ``self.excluded_pixels`` is then the mask of the
        pixels whose hit fell in ``exclude`` (the robot's own)."""
        R, t = T_root_camera[:3, :3], T_root_camera[:3, 3]
        inv = 1.0 / self.resolution
        valid = np.isfinite(depth)
        measured = int(np.count_nonzero(valid))
        steps = int(math.ceil(thickness / (self.resolution / 2) - 1e-9)) if thickness > 0 else 0
        slopes = []
        for k in range(3):
            # voxel coordinate along axis k, in voxel units: (depth * (R_k . ray) + t_k - origin_k) / h
            row = ((R[k, 1] * ray_y + R[k, 2]) * inv).astype(np.float32)[:, None]
            col = (R[k, 0] * ray_x * inv).astype(np.float32)[None, :]
            slopes.append(row + col)
        found = []
        kept_pixels = 0
        offsets = [np.float32((t[k] - self.origin[k]) * inv) for k in range(3)]
        strides = [np.int32(v) for v in self._strides]
        for layer in range(steps + 1):
            shifted = depth + np.float32(min(layer * self.resolution / 2, thickness)) if layer else depth
            # per axis the voxel coordinate (float32, NaN for no measurement: every comparison with it is False)
            inside = None
            key = None
            for k in range(3):
                f = shifted * slopes[k]
                f += offsets[k]
                ok = f >= 0
                ok &= f < self.shape[k]
                inside = ok if inside is None else inside & ok
                with np.errstate(invalid="ignore"):  # NaN pixels cast to garbage, masked by `inside`
                    cell = f.astype(np.int32)
                if key is None:
                    key = cell * strides[k]
                elif k == 1:
                    key += cell * strides[k]
                else:
                    key += cell
            keys = key[inside].astype(np.int64)
            if not layer:
                kept_pixels = len(keys)
                first_keys, first_inside = keys, inside
            found.append(keys)
        keys = np.concatenate(found) if steps else found[0]
        self.dropped_outside += measured - kept_pixels
        self.excluded_pixels = np.zeros(depth.shape, dtype=bool)
        if exclude is not None and len(exclude):
            self._scratch[exclude] = True
            keys = keys[~self._scratch[keys]]
            self.excluded_pixels[first_inside] = self._scratch[first_keys]
            self._scratch[exclude] = False
        self.occupied[keys] = True
        self.free[keys] = False
        if self.seen is not None:
            self.seen[keys] = stamp
        self.version += 1
        return measured, kept_pixels

    def mark_seen_free(
        self,
        depth: np.ndarray,
        intrinsics: tuple[float, float, float, float],
        T_root_camera: np.ndarray,
        margin: float,
        *,
        max_range: float = math.inf,
        ignore: np.ndarray | None = None,
        keep_into_nothing: bool = False,
    ) -> int:
        """Update the region's unknown voxels from a depth image (metres, NaN = no measurement). Each voxel is
        judged by the nearest valid depth of the 3x3 pixels around its centre's (a missing pixel, or a voxel wider
        than a pixel, hides nothing): known free when that depth is more than ``margin`` [m] beyond the centre (the
        whole box is in front of the surface when ``margin`` is at least half the voxel's diagonal);
        ``shadowed`` when it is not (a surface is in front of the voxel or in it); ``viewed`` when the centre
        projects into the image within ``max_range`` (a voxel viewed only through pixels without any measurement
        around them, looking into nothing, is neither). ``ignore``: a mask of pixels taken as no measurement (the
        robot's own bodies: they free nothing and, in this mode, shadow nothing). Returns how many became known
        free."""
        keys = self._region_keys
        if not len(keys):
            return 0
        fx, fy, cx, cy = intrinsics
        H, W = depth.shape
        corner = max(abs(cx), abs(W - cx)) / fx, max(abs(cy), abs(H - cy)) / fy
        half_angle = math.atan(math.hypot(*corner))  # the cone around the image's frustum
        candidates = self._region_in_view(T_root_camera[:3, 3], T_root_camera[:3, 2], half_angle, max_range)
        unknown = np.flatnonzero(candidates & ~(self.occupied[keys] | self.free[keys]))
        keys, centres = keys.take(unknown), self._region_centres.take(unknown, axis=0)
        if not len(keys):
            return 0
        R, t = T_root_camera[:3, :3].astype(np.float32), T_root_camera[:3, 3].astype(np.float32)
        local = (centres - t) @ R  # camera frame
        z = local[:, 2]
        ahead = np.flatnonzero((z > 1e-3) & (z <= max_range))
        z = z[ahead]
        u = np.floor(np.float32(fx) * local[ahead, 0] / z + np.float32(cx))
        v = np.floor(np.float32(fy) * local[ahead, 1] / z + np.float32(cy))
        inside = (u >= 0) & (u < W) & (v >= 0) & (v < H)
        rows, z = ahead[inside], z[inside]
        pixel = v[inside].astype(np.int64) * W + u[inside].astype(np.int64)
        own = np.zeros(depth.shape, dtype=np.float32) if ignore is None else ignore.astype(np.float32)
        if ignore is not None:
            depth = np.where(ignore, np.nan, depth)
        measured = _nearest_around(depth).reshape(-1)[pixel]
        self.viewed[keys[rows]] = True
        finite = np.isfinite(measured)
        seen = finite & (measured > z + np.float32(margin))
        # the rule added with the kernels: a voxel viewed into nothing (no return, no robot pixel around) is not
        # shadowed again by later images
        around_own = _nearest_around(np.where(own > 0, 1.0, np.nan).astype(np.float32)).reshape(-1)[pixel] == 1.0
        self.into_nothing[keys[rows[~finite & ~around_own]]] = True
        hidden = rows[finite & ~seen]
        if keep_into_nothing:
            hidden = hidden[~self.into_nothing[keys[hidden]]]
        self.shadowed[keys[hidden]] = True
        found = keys[rows[seen]]
        self.free[found] = True
        self.version += 1
        return len(found)

    def near_segments(self, starts: np.ndarray, ends: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """Keys of the voxels whose box may come within ``radii`` [m] of a segment (the robot's bodies plus
        padding): the voxel's centre is within ``radius + half diagonal``. Every point within ``radius`` of a segment
        falls in one of them."""
        found = []
        half = self.resolution * math.sqrt(3) / 2
        h = self.resolution
        for s, e, r in zip(
            np.asarray(starts, dtype=float), np.asarray(ends, dtype=float), np.asarray(radii), strict=True
        ):
            reach = float(r) + half
            lo = np.maximum(np.floor((np.minimum(s, e) - reach - self.origin) / h).astype(int), 0)
            hi = np.minimum(np.floor((np.maximum(s, e) + reach - self.origin) / h).astype(int) + 1, self.shape)
            if np.any(hi <= lo):
                continue
            # voxel centres relative to the segment start, one axis per array dimension (broadcast, no grid)
            x, y, z = (self.origin[k] + (np.arange(lo[k], hi[k]) + 0.5) * h - s[k] for k in range(3))
            x, y, z = x[:, None, None], y[None, :, None], z[None, None, :]
            u = e - s
            length2 = float(u @ u)
            t = np.clip((x * u[0] + y * u[1] + z * u[2]) / length2, 0.0, 1.0) if length2 > 1e-18 else 0.0
            near = (x - t * u[0]) ** 2 + (y - t * u[1]) ** 2 + (z - t * u[2]) ** 2 <= reach * reach
            i, j, k = np.nonzero(near)
            found.append((i + lo[0]) * self._strides[0] + (j + lo[1]) * self._strides[1] + (k + lo[2]))
        return np.concatenate(found) if found else np.zeros(0, dtype=np.int64)


@pytest.fixture(scope="module")
def robot() -> taplan.Robot:
    return taplan.Robot.teleavatar()


def _views(robot: taplan.Robot, count: int, seed: int) -> list[tuple[str, np.ndarray]]:
    """Seeded arm configurations (inside the planning limits) with the wrist camera of the moved arm."""
    rng = np.random.default_rng(seed)
    limits = robot.planning_limits
    views = []
    for k in range(count):
        q = limits.lower + rng.uniform(0.15, 0.85, robot.nq) * (limits.upper - limits.lower)
        views.append(("left_depth_camera" if k % 2 == 0 else "right_depth_camera", q))
    return views


@pytest.mark.parametrize(
    ("family", "unknown", "thickness", "decay", "nothing"),
    [
        ("table_box", "occluded", 0.0, None, False),
        ("poles", "occluded", 0.0, None, True),
        ("shelf", "occupied", 0.03, 5.0, False),
        ("poles", "free", 0.0, None, False),
    ],
)
def test_compiled_fusion_leaves_the_numpy_codes_voxel_states(robot, family, unknown, thickness, decay, nothing) -> None:
    scene = make_scene(family, np.random.default_rng(3))
    compiled = Perception(robot, resolution=0.02, unknown=unknown, thickness=thickness, decay=decay)
    reference = Perception(robot, resolution=0.02, unknown=unknown, thickness=thickness, decay=decay)
    reference.grid.__class__ = NumpyGrid
    rng = np.random.default_rng(11)
    excluded = 0
    for step, (frame, q) in enumerate(_views(robot, 8, seed=5)):
        T = compiled.frame_pose(frame, q)
        starts, ends, radii = compiled.robot_segments(q)
        depth = render_depth(
            CAMERA, T, scene, capsules=zip(starts, ends, radii, strict=True), noise=0.003, missing=0.03, rng=rng
        )
        answers = [
            p.integrate_depth(
                depth, CAMERA, frame=frame, q=q, stamp=0.5 * step, robot_there=step % 3 != 0, nothing_unshadows=nothing
            )
            for p in (compiled, reference)
        ]
        assert answers[0].measured == answers[1].measured and answers[0].kept == answers[1].kept
        assert answers[0].cleared == answers[1].cleared
        a, b = compiled.grid, reference.grid
        np.testing.assert_array_equal(a.excluded_pixels, b.excluded_pixels)
        excluded += int(np.count_nonzero(a.excluded_pixels))
        for state in ("occupied", "free", "viewed", "shadowed", "into_nothing"):
            np.testing.assert_array_equal(getattr(a, state), getattr(b, state), err_msg=f"{state} after image {step}")
        if decay is not None:
            np.testing.assert_array_equal(a.seen, b.seen)
        assert a.dropped_outside == b.dropped_outside
    # the comparison means something: the robot was in view, surfaces were hit, space was seen free
    assert excluded > 100
    assert np.count_nonzero(compiled.grid.occupied) > 500
    assert unknown == "free" or np.count_nonzero(compiled.grid.free) > 10_000
    assert unknown == "free" or np.count_nonzero(compiled.grid.into_nothing) > 1000


def test_voxels_near_the_bodies_are_the_numpy_codes(robot) -> None:
    grid, reference = OccupancyGrid(0.02), NumpyGrid(0.02)
    perception = Perception(robot)
    for q in [robot.home] + [q for _, q in _views(robot, 6, seed=2)]:
        starts, ends, radii = perception.robot_segments(q)
        for padding in (0.0, 0.02, 0.05):
            ours = grid.near_segments(starts, ends, radii + padding)
            np.testing.assert_array_equal(ours, reference.near_segments(starts, ends, radii + padding))
            assert len(ours) > 1000
    # a degenerate segment (a sphere) and one reaching out of the bounds
    point = np.array([[1.39, 0.0, 0.0]])
    np.testing.assert_array_equal(
        grid.near_segments(point, point, np.array([0.05])), reference.near_segments(point, point, np.array([0.05]))
    )
