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
from taplan.scene.perception import Perception
from taplan.scene.raycast import render_depth
from taplan.scene.scene import Scene

__all__ = ["scan_configurations", "perceive", "WORKSPACE"]

WORKSPACE = ((0.2, -0.7, -0.7), (1.0, 0.7, 0.2))  # [m] in front of the TeleAvatar, root frame
_PROBE = PinholeCamera(32, 24, 16.85, 16.85, 16.0, 12.0)  # the wrist camera's field of view at 1/20 resolution


def _seen_cells(depth: np.ndarray, camera: PinholeCamera, T: np.ndarray, box: tuple[Any, Any], cell: float) -> set:
    """The ``cell``-sized cells of the box that the image's hits fall in."""
    points = camera.points(depth) @ T[:3, :3].T + T[:3, 3]
    lo, hi = np.asarray(box[0]), np.asarray(box[1])
    points = points[np.all((points >= lo) & (points <= hi), axis=1)]
    return set(map(tuple, np.floor((points - lo) / cell).astype(int).tolist()))


def scan_configurations(
    perception: Perception,
    scene: Scene,
    *,
    count: int = 5,
    samples: int = 80,
    seed: int = 0,
    workspace: tuple[Any, Any] = WORKSPACE,
    cell: float = 0.05,
) -> list[tuple[str, np.ndarray]]:
    """Up to ``count`` ``(camera frame, configuration)`` per wrist camera, chosen greedily among ``samples`` seeded
    draws of that arm (the other at home) within the planning limits: each next view is the one whose hits cover
    the most ``cell``-sized cells [m] of ``workspace`` that no chosen view covers yet (a next-best-view rule)."""
    robot = perception.robot
    rng = np.random.default_rng(seed)
    limits = robot.planning_limits
    out: list[tuple[str, np.ndarray]] = []
    covered: set = set()
    candidates = []
    for frame in perception.cameras:
        arm = "left" if "left" in frame else "right"
        idx = robot.group(arm).indices
        for _ in range(samples):
            q = robot.home.copy()
            q[idx] = limits.lower[idx] + rng.uniform(0.05, 0.95, len(idx)) * (limits.upper[idx] - limits.lower[idx])
            T = perception.frame_pose(frame, q)
            depth = render_depth(_PROBE, T, scene, max_range=perception.max_range)
            candidates.append((frame, q, _seen_cells(depth, _PROBE, T, workspace, cell)))
    chosen = {frame: 0 for frame in perception.cameras}
    while candidates:
        k = max(range(len(candidates)), key=lambda i: len(candidates[i][2] - covered))
        frame, q, cells = candidates.pop(k)
        if not cells - covered:
            break
        if chosen[frame] < count:
            chosen[frame] += 1
            covered |= cells
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
