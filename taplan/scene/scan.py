"""Looking around with the wrist cameras: configurations that see a workspace, and a perceived scene built from
the depth images rendered there (the simulator's, the tests' and the notebook's way to "see" a scene file).

:func:`scan_configurations` samples arm configurations (seeded) and keeps those whose wrist camera sees most of a
workspace box, with camera positions kept apart for different viewpoints. :func:`perceive` renders each camera at
each configuration (the scene's primitives and the robot's own bodies, with noise and missing pixels) and fuses the
images into a :class:`~taplan.scene.perception.Perception`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from taplan.scene.camera import TELEAVATAR_CAMERAS, WRIST_DEPTH_CAMERA, PinholeCamera
from taplan.scene.perception import DEFAULT_WORKSPACE, Perception
from taplan.scene.raycast import render_depth
from taplan.scene.scene import Scene

__all__ = ["scan_configurations", "perceive", "views_seeing", "RenderedViews", "WORKSPACE"]

WORKSPACE = DEFAULT_WORKSPACE  # [m] in front of the TeleAvatar, root frame
_PROBE = PinholeCamera(32, 24, 16.85, 16.85, 16.0, 12.0)  # the wrist camera's field of view at 1/20 resolution
MAX_FOCUS_POINTS = 4000  # voxels of a focus configuration's bodies scored per view (a seeded subset)


def _cell_centres(workspace: tuple[Any, Any], cell: float) -> np.ndarray:
    lo, hi = np.asarray(workspace[0], dtype=float), np.asarray(workspace[1], dtype=float)
    axes = [np.arange(a + cell / 2, b, cell) for a, b in zip(lo, hi, strict=True)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def _seen_cells(
    depth: np.ndarray, camera: PinholeCamera, T: np.ndarray, centres: np.ndarray, slack: np.ndarray
) -> np.ndarray:
    """Which points (centres (M, 3)) an image sees: the ray through the point's pixel reaches at least to the point's
    depth plus its ``slack`` [m] (M,) (negative for a cell: seen free or its surface seen; positive for a voxel that
    must be seen past to be known free)."""
    local = (centres - T[:3, 3]) @ T[:3, :3]
    z = local[:, 2]
    ahead = z > 1e-3
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.floor(camera.fx * local[:, 0] / z + camera.cx)
        v = np.floor(camera.fy * local[:, 1] / z + camera.cy)
    inside = ahead & (u >= 0) & (u < camera.width) & (v >= 0) & (v < camera.height)
    seen = np.zeros(len(centres), dtype=bool)
    rows = np.flatnonzero(inside)
    measured = depth[v[rows].astype(int), u[rows].astype(int)]
    with np.errstate(invalid="ignore"):
        seen[rows] = measured >= z[rows] + slack[rows]
    return seen


def scan_configurations(
    perception: Perception,
    scene: Scene,
    *,
    count: int = 5,
    samples: int = 80,
    seed: int = 0,
    workspace: tuple[Any, Any] = WORKSPACE,
    cell: float = 0.05,
    focus: Any = (),
    focus_weight: float = 10.0,
) -> list[tuple[str, np.ndarray]]:
    """Up to ``count`` ``(camera frame, configuration)`` per wrist camera, chosen greedily among ``samples`` seeded
    draws of that arm (the other at home) within the planning limits: each next view is the one that sees the most
    ``cell``-sized cells [m] of ``workspace`` no chosen view has seen (seen: free up to the cell or its surface
    seen; a next-best-view rule on unknown space). ``focus``: configurations the robot will take (a plan's goal);
    the cells their bodies fill weigh ``focus_weight`` times as much (look where the arm is going)."""
    robot = perception.robot
    rng = np.random.default_rng(seed)
    limits = robot.planning_limits
    centres = _cell_centres(workspace, cell)
    slack = np.full(len(centres), -cell / 2)
    weight = np.ones(len(centres))
    grid = perception.grid
    for q in focus:
        # the voxels of the workspace the robot's padded bodies will fill there, each to be seen past
        starts, ends, radii = perception.robot_segments(robot.check_configuration(q, "focus"))
        keys = grid.near_segments(starts, ends, radii + perception.padding)
        points = grid.centers(np.unique(keys))
        lo, hi = np.asarray(workspace[0]), np.asarray(workspace[1])
        points = points[np.all((points >= lo) & (points <= hi), axis=1)]
        points = points[rng.permutation(len(points))[:MAX_FOCUS_POINTS]]
        centres = np.concatenate([centres, points])
        slack = np.concatenate([slack, np.full(len(points), perception.free_margin)])
        weight = np.concatenate([weight, np.full(len(points), focus_weight)])
    candidates = []
    for frame in perception.cameras:
        arm = "left" if "left" in frame else "right"
        idx = robot.group(arm).indices
        for _ in range(samples):
            q = robot.home.copy()
            q[idx] = limits.lower[idx] + rng.uniform(0.05, 0.95, len(idx)) * (limits.upper[idx] - limits.lower[idx])
            T = perception.frame_pose(frame, q)
            starts, ends, radii = perception.robot_segments(q)  # the robot's own bodies hide what is behind them
            bodies = zip(starts, ends, radii, strict=True)
            depth = render_depth(_PROBE, T, scene, capsules=bodies, max_range=perception.max_range)
            candidates.append((frame, q, _seen_cells(depth, _PROBE, T, centres, slack)))
    out: list[tuple[str, np.ndarray]] = []
    chosen = {frame: 0 for frame in perception.cameras}
    covered = np.zeros(len(centres), dtype=bool)
    while candidates:
        gains = [float(weight[seen & ~covered].sum()) for _, _, seen in candidates]
        k = int(np.argmax(gains))
        frame, q, seen = candidates.pop(k)
        if gains[k] <= 0:
            break
        if chosen[frame] < count:
            chosen[frame] += 1
            covered |= seen
            out.append((frame, q))
    return out


def perceive(
    robot: Any,
    scene: Scene,
    views: list[tuple[str, np.ndarray]] | None = None,
    *,
    camera: PinholeCamera = WRIST_DEPTH_CAMERA,
    noise: float = 0.002,
    missing: float = 0.02,
    seed: int = 0,
    resolution: float = 0.02,
    thickness: float = 0.0,
    **options: Any,
) -> Perception:
    """A :class:`Perception` of ``scene`` from depth images rendered at ``views`` (``(camera frame,
    configuration)``; default :func:`scan_configurations`), the robot's own bodies drawn too. Surfaces are taken
    as solids ``thickness`` [m] thick (what a camera cannot see behind a table top is table)."""
    perception = Perception(
        robot, resolution=resolution, thickness=thickness, cameras=dict(TELEAVATAR_CAMERAS), **options
    )
    views = scan_configurations(perception, scene, seed=seed) if views is None else views
    rng = np.random.default_rng(seed)
    for frame, q in views:
        T = perception.frame_pose(frame, q)
        starts, ends, radii = perception.robot_segments(q)
        depth = render_depth(
            camera,
            T,
            scene,
            capsules=zip(starts, ends, radii, strict=True),
            max_range=perception.max_range,
            noise=noise,
            missing=missing,
            rng=rng,
        )
        perception.integrate_depth(depth, camera, frame=frame, q=q)
    perception.update_scene()
    return perception


def _line_of_sight(perception: Perception, eye: np.ndarray, points: np.ndarray, beyond: float) -> np.ndarray:
    """Which ``points`` (M, 3) an eye at ``eye`` could see ``beyond`` [m] past: no occupied voxel of the map lies on
    the segment from the eye to that far (sampled every half voxel; the first ``min_range`` is the camera's own)."""
    grid = perception.grid
    offset = points - eye
    distance = np.linalg.norm(offset, axis=1)
    direction = offset / np.maximum(distance, 1e-9)[:, None]
    step = grid.resolution / 2
    s = np.arange(perception.min_range, float(distance.max()) + beyond + step, step)
    samples = eye + direction[:, None, :] * s[None, :, None]  # (M, S, 3)
    cell = np.floor((samples - grid.origin) / grid.resolution).astype(np.int64)
    inside = np.all((cell >= 0) & (cell < grid.shape), axis=2)
    key = np.where(inside, cell @ grid._strides, 0)
    blocked = inside & grid.occupied[key] & (s[None, :] <= (distance + beyond)[:, None])
    # the point's own voxel and the ones just past it are what the view is to find out: only what lies before counts
    blocked &= s[None, :] < (distance - grid.resolution)[:, None]
    return ~blocked.any(axis=1)


def views_seeing(
    perception: Perception,
    points: Any,
    *,
    base: Any = None,
    camera: PinholeCamera = WRIST_DEPTH_CAMERA,
    count: int = 4,
    samples: int = 60,
    seed: int = 0,
    clear_of: Any = None,
    clearance: float = 0.0,
    max_points: int = 600,
    extra: Any = (),
) -> list[tuple[str, np.ndarray]]:
    """Up to ``count`` ``(camera frame, configuration)`` whose wrist camera would see past the most of ``points``
    (N, 3) [m, root frame]: what a plan sweeps but no image has seen. Candidates are ``samples`` seeded draws of each
    wrist camera's arm (the other arm at ``base``, default home) within the planning limits; with ``clear_of`` (a
    :class:`~taplan.scene.CollisionWorld` of what is known: occupied and unseen space) only configurations more than
    ``clearance`` [m] from it are candidates (the arm may only stand where the map says it is free). A point counts
    as seen from a candidate when it projects into ``camera``'s image within range, neither an occupied voxel of the
    map nor the robot's own bodies lie on the line of sight, and the sight reaches ``free_margin`` beyond it; the
    views are chosen greedily for the most points not yet seen. Only the map is used, never the true scene: the
    choice is a prediction that the capture confirms or not. ``extra``: more candidate ``(camera frame,
    configuration)`` (e.g. aimed at the points by IK)."""
    robot = perception.robot
    rng = np.random.default_rng(seed)
    P = np.asarray(points, dtype=float).reshape(-1, 3)
    if not len(P):
        return []
    P = P[rng.permutation(len(P))[:max_points]]
    base_q = robot.home.copy() if base is None else robot.check_configuration(base, "base")
    limits = robot.planning_limits
    scale = max(1, camera.width // 32)
    probe = PinholeCamera(
        camera.width // scale,
        camera.height // scale,
        camera.fx / scale,
        camera.fy / scale,
        camera.cx / scale,
        camera.cy / scale,
    )
    beyond = perception.free_margin
    drawn = []
    for frame in perception.cameras:
        arm = "left" if "left" in frame else "right"
        idx = robot.group(arm).indices
        for _ in range(samples):
            q = base_q.copy()
            q[idx] = limits.lower[idx] + rng.uniform(0.05, 0.95, len(idx)) * (limits.upper[idx] - limits.lower[idx])
            drawn.append((frame, q))
    candidates = []
    for frame, q in [*extra, *drawn]:
        T = perception.frame_pose(frame, q)
        local = (P - T[:3, 3]) @ T[:3, :3]
        z = local[:, 2]
        ok = (z > perception.min_range) & (z + beyond < perception.max_range)
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.floor(probe.fx * local[:, 0] / z + probe.cx)
            v = np.floor(probe.fy * local[:, 1] / z + probe.cy)
        ok &= (u >= 0) & (u < probe.width) & (v >= 0) & (v < probe.height)
        rows = np.flatnonzero(ok)
        if not len(rows):
            continue
        starts, ends, radii = perception.robot_segments(q)  # the own gripper hides a quarter of the image
        own = render_depth(probe, T, None, capsules=zip(starts, ends, radii, strict=True), max_range=10.0)
        rows = rows[~(own[v[rows].astype(int), u[rows].astype(int)] < z[rows] + beyond)]  # NaN: nothing hit
        if not len(rows):
            continue
        seen = np.zeros(len(P), dtype=bool)
        seen[rows] = _line_of_sight(perception, T[:3, 3], P[rows], beyond)
        # the collision query last: the costliest test, for the few candidates that would see something
        if seen.any() and (clear_of is None or clear_of.min_distance(q)[0] > clearance):
            candidates.append((frame, q, seen))
    out: list[tuple[str, np.ndarray]] = []
    covered = np.zeros(len(P), dtype=bool)
    while candidates and len(out) < count:
        gains = [int(np.count_nonzero(seen & ~covered)) for _, _, seen in candidates]
        k = int(np.argmax(gains))
        if gains[k] == 0:
            break
        frame, q, seen = candidates.pop(k)
        covered |= seen
        out.append((frame, q))
    return out


class RenderedViews:
    """The simulated capture: ``capture(frame, q)`` renders the depth image the wrist camera ``frame`` takes with the
    robot at ``q`` (``scene``'s primitives and the robot's own bodies, seeded noise and missing pixels) and returns
    ``(depth [m], camera)``. The arm is not moved there: nothing plans or checks the motion to the view (on the
    robot, the capture callable moves the arm with a plan in the seen space and returns the next image)."""

    def __init__(
        self,
        perception: Perception,
        scene: Scene,
        *,
        camera: PinholeCamera = WRIST_DEPTH_CAMERA,
        noise: float = 0.002,
        missing: float = 0.02,
        seed: int = 0,
    ) -> None:
        self.perception, self.scene, self.camera = perception, scene, camera
        self.noise, self.missing = float(noise), float(missing)
        self.rng = np.random.default_rng(seed)
        self.count = 0

    def __call__(self, frame: str, q: np.ndarray) -> tuple[np.ndarray, PinholeCamera]:
        perception = self.perception
        T = perception.frame_pose(frame, q)
        starts, ends, radii = perception.robot_segments(q)
        depth = render_depth(
            self.camera,
            T,
            self.scene,
            capsules=zip(starts, ends, radii, strict=True),
            max_range=perception.max_range,
            noise=self.noise,
            missing=self.missing,
            rng=self.rng,
        )
        self.count += 1
        return depth, self.camera
