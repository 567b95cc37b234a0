"""The TeleAvatar's wrist depth camera mounts as plain transforms: a leaf of the package (numpy only), so the robot
model gets these frames when it is loaded (:meth:`taplan.Robot.teleavatar`) and :mod:`taplan.scene.camera` names
them :data:`~taplan.scene.camera.TELEAVATAR_CAMERAS` (with where each number comes from: all estimates)."""

from __future__ import annotations

import numpy as np

__all__ = ["TELEAVATAR_CAMERA_FRAMES"]


def _camera_frame(xyz: list[float], z_axis: list[float], down: list[float], tilt: float) -> np.ndarray:
    """``T_parent_camera`` of an optical frame (z forward, y image-down) at ``xyz`` looking along ``z_axis`` with
    image-down ``down``, tilted by ``tilt`` [rad] toward ``down``."""
    z_axis_, down_ = np.array(z_axis, dtype=float), np.array(down, dtype=float)
    z = z_axis_ * np.cos(tilt) + down_ * np.sin(tilt)
    y = down_ * np.cos(tilt) - z_axis_ * np.sin(tilt)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([np.cross(y, z), y, z])
    T[:3, 3] = xyz
    return T


# The wrist depth cameras' mounts (estimates: see taplan.scene.camera.TELEAVATAR_CAMERAS). The tool axis is +y of
# Link-L7 and -y of Link-R7 (the fingers Link-L10/L11 sit at y = +0.177 m, Link-R10/R11 at -0.177 m in the vendor
# URDF); the fingers are on the -z side (z = -0.023 .. -0.039 m).
TELEAVATAR_CAMERA_FRAMES: dict[str, tuple[str, np.ndarray]] = {
    "left_depth_camera": ("Link-L7", _camera_frame([0.0, 0.05, 0.06], [0, 1, 0], [0, 0, -1], 0.35)),
    "right_depth_camera": ("Link-R7", _camera_frame([0.0, -0.05, 0.06], [0, -1, 0], [0, 0, -1], 0.35)),
}
