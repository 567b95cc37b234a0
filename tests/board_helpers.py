"""The board scene shared by the unknown-space and look-where-you-go tests: a thin board below the hands at home,
a small wrist-camera model and a workspace around the board (smaller than the default: faster tests)."""

from __future__ import annotations

import numpy as np

from taplan.scene import Box, Scene
from taplan.scene.camera import PinholeCamera

SMALL = PinholeCamera(160, 120, 84.25, 84.25, 80.0, 60.0)  # the wrist camera's field of view at 1/4 resolution
BOARD_CENTRE = np.array([0.65, 0.0, -0.35])  # below the hands at home
BOARD_SIZE = (0.35, 0.5, 0.02)
WORKSPACE = ((0.3, -0.45, -0.6), (1.0, 0.45, -0.1))


def board_scene() -> Scene:
    scene = Scene()
    scene.add("board", Box(BOARD_SIZE), (BOARD_CENTRE.tolist(), [0, 0, 0, 1]))
    return scene
