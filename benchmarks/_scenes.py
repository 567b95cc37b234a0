"""A seeded suite of TeleAvatar planning problems in five scene families (anyone can regenerate it).

Families: ``table`` (a table in front of the robot), ``table_box`` (plus a box on it), ``shelf`` (two boards: slots
at two heights), ``panel`` (a vertical panel between the hands), ``clutter`` (a table with 10-30 random boxes).
Problems: start and goal configurations drawn within the planning limits for one arm (the other at home) or both,
collision-free with the planner's margin; the goal is a joint configuration or the pose(s) of the moved hand(s)'
``*_tcp`` frame at the goal configuration. Rejection sampling keeps only problems whose straight joint-space
segment is *not* free in half of the problems (``hard`` ones), so the suite exercises the detours.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

import taplan
from taplan.planning.verify import check_segment
from taplan.scene import Box, CollisionWorld, HalfSpace, Scene

FAMILIES = ("table", "table_box", "shelf", "panel", "clutter")
MARGIN = 0.01  # [m] the planner's default


@dataclass(frozen=True)
class Problem:
    family: str
    index: int
    scene: Scene
    start: np.ndarray
    goal: Any  # (nq,) or {frame: 4x4}
    goal_q: np.ndarray
    arms: tuple[str, ...]
    kind: str  # "joint" or "pose"


def make_scene(family: str, rng: np.random.Generator) -> Scene:
    scene = Scene()
    height = rng.uniform(-0.5, -0.4)
    scene.add("floor", HalfSpace(), ([0.0, 0.0, -1.0], [0, 0, 0, 1]))
    if family in ("table", "table_box", "clutter"):
        scene.add("table", Box((0.6, 1.2, 0.04)), ([rng.uniform(0.5, 0.6), 0.0, height], [0, 0, 0, 1]))
    if family == "table_box":
        scene.add(
            "box", Box((0.15, 0.2, 0.2)), ([rng.uniform(0.4, 0.5), rng.uniform(-0.1, 0.1), height + 0.12], [0, 0, 0, 1])
        )
    if family == "shelf":
        x = rng.uniform(0.5, 0.6)
        for k, z in enumerate((-0.45, -0.2, 0.05)):
            scene.add(f"board{k}", Box((0.35, 1.0, 0.02)), ([x, 0.0, z + rng.uniform(-0.02, 0.02)], [0, 0, 0, 1]))
        scene.add("back", Box((0.02, 1.0, 0.55)), ([x + 0.18, 0.0, -0.2], [0, 0, 0, 1]))
    if family == "panel":
        scene.add(
            "panel", Box((0.5, 0.02, 0.5)), ([rng.uniform(0.45, 0.55), rng.uniform(-0.03, 0.03), -0.2], [0, 0, 0, 1])
        )
    if family == "clutter":
        for k in range(int(rng.integers(10, 31))):
            size = rng.uniform(0.03, 0.08, 3)
            xy = rng.uniform([0.35, -0.5], [0.8, 0.5])
            scene.add(f"clutter{k}", Box(tuple(size)), ([xy[0], xy[1], height + 0.02 + size[2] / 2], [0, 0, 0, 1]))
    return scene


def _sample(
    robot: taplan.Robot, world: CollisionWorld, arms: tuple[str, ...], rng: np.random.Generator
) -> np.ndarray | None:
    limits = robot.planning_limits
    for _ in range(200):
        q = robot.home.copy()
        for arm in arms:
            idx = robot.group(arm).indices
            q[idx] = limits.lower[idx] + rng.uniform(0.05, 0.95, len(idx)) * (limits.upper[idx] - limits.lower[idx])
        if world.min_distance(q)[0] >= MARGIN * 1.5:
            return q
    return None


def problems(count: int, seed: int = 0) -> list[Problem]:
    """``count`` problems spread over the families (seeded)."""
    robot = taplan.Robot.teleavatar()
    rng = np.random.default_rng(seed)
    out: list[Problem] = []
    i = 0
    while len(out) < count:
        family = FAMILIES[i % len(FAMILIES)]
        i += 1
        scene = make_scene(family, rng)
        world = CollisionWorld(robot, scene)
        arms = (("left",), ("right",), ("left", "right"))[int(rng.integers(3))]
        hard = len(out) % 2 == 0
        for _ in range(20):
            start = _sample(robot, world, arms, rng)
            goal = _sample(robot, world, arms, rng)
            if start is None or goal is None:
                continue
            blocked = not check_segment(world, start, goal, MARGIN).valid
            if blocked == hard:
                break
        else:
            continue
        kind = "pose" if rng.uniform() < 0.5 else "joint"
        target: Any = goal
        if kind == "pose":
            target = {f"{arm}_tcp": robot.frame_pose(goal, f"{arm}_tcp") for arm in arms}
        out.append(Problem(family, len(out), scene, start, target, goal, arms, kind))
    return out
