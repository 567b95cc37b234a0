"""A seeded suite of TeleAvatar planning problems in thirteen scene families (anyone can regenerate it).

Families: ``table`` (a table in front of the robot), ``table_box`` (plus a box on it), ``shelf`` (two boards: slots
at two heights), ``panel`` (a vertical panel between the hands), ``clutter`` (a table with 10-30 random boxes); and
those of issue 27: ``window`` (a 2 cm wall across the workspace with a 25-32 cm opening), ``overhang`` (a board over
a table), ``cabinet`` (open front), ``poles`` (3-6 poles of 2-4 cm), ``chest_box`` (a box against the chest),
``divider`` (a wall between the arms), ``attached`` (a table, a cylinder carried in each hand), ``cubby`` (a 2 x 2
grid of cells).
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
from taplan.scene import Box, CollisionWorld, Cylinder, HalfSpace, Scene

FAMILIES = (
    "table",
    "table_box",
    "shelf",
    "panel",
    "clutter",
    "window",
    "overhang",
    "cabinet",
    "poles",
    "chest_box",
    "divider",
    "attached",
    "cubby",
)
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
    _add_hard_family(scene, family, height, rng)
    return scene


def _board(scene: Scene, name: str, size: tuple[float, float, float], xyz: Any) -> None:
    scene.add(name, Box(size), (list(map(float, xyz)), [0, 0, 0, 1]))


def _add_hard_family(scene: Scene, family: str, height: float, rng: np.random.Generator) -> None:
    """The families of issue 27 (thin walls, openings a few centimetres wider than the arm, carried objects)."""
    if family == "window":  # a 2 cm wall across the workspace with a square opening in front of one arm
        x, side = rng.uniform(0.35, 0.45), rng.choice([-1.0, 1.0])
        cy, cz, w = side * rng.uniform(0.2, 0.4), rng.uniform(-0.3, -0.05), rng.uniform(0.25, 0.32)
        _board(scene, "wall_below", (0.02, 1.6, cz - w / 2 + 0.8), (x, 0.0, (cz - w / 2 - 0.8) / 2))
        _board(scene, "wall_above", (0.02, 1.6, 0.5 - cz - w / 2), (x, 0.0, (0.5 + cz + w / 2) / 2))
        left, right = cy + w / 2, cy - w / 2
        _board(scene, "wall_left", (0.02, 0.8 - left, w), (x, (0.8 + left) / 2, cz))
        _board(scene, "wall_right", (0.02, right + 0.8, w), (x, (right - 0.8) / 2, cz))
    elif family == "overhang":  # a table and a board over it, a hand's height above
        x = rng.uniform(0.5, 0.6)
        scene.add("table", Box((0.6, 1.2, 0.04)), ([x, 0.0, height], [0, 0, 0, 1]))
        _board(scene, "overhang", (0.35, 1.2, 0.02), (x + 0.12, 0.0, height + rng.uniform(0.22, 0.3)))
    elif family == "cabinet":  # an open-front cabinet: back, sides, top and bottom
        x, z, depth, width, tall = rng.uniform(0.5, 0.6), rng.uniform(-0.4, -0.3), 0.35, 0.9, 0.45
        _board(scene, "cabinet_bottom", (depth, width, 0.02), (x, 0.0, z))
        _board(scene, "cabinet_top", (depth, width, 0.02), (x, 0.0, z + tall))
        _board(scene, "cabinet_back", (0.02, width, tall), (x + depth / 2, 0.0, z + tall / 2))
        for name, y in (("cabinet_left", width / 2), ("cabinet_right", -width / 2)):
            _board(scene, name, (depth, 0.02, tall), (x, y, z + tall / 2))
    elif family == "poles":  # thin vertical poles (2-4 cm) in front of the robot
        for k in range(int(rng.integers(3, 7))):
            xy = rng.uniform([0.3, -0.6], [0.7, 0.6])
            scene.add(f"pole{k}", Cylinder(rng.uniform(0.01, 0.02), 1.2), ([xy[0], xy[1], -0.4], [0, 0, 0, 1]))
    elif family == "chest_box":  # a box held against the chest
        size = rng.uniform([0.12, 0.2, 0.12], [0.2, 0.35, 0.2])
        _board(scene, "chest_box", tuple(size), (0.12 + size[0] / 2 + rng.uniform(0.0, 0.06), 0.0, -0.2))
    elif family == "divider":  # a thin wall between the arms, from the chest forward
        _board(scene, "divider", (0.7, 0.02, 0.9), (rng.uniform(0.45, 0.55), rng.uniform(-0.03, 0.03), -0.25))
    elif family == "attached":  # a table, and a cylinder carried in each hand
        scene.add("table", Box((0.6, 1.2, 0.04)), ([rng.uniform(0.5, 0.6), 0.0, height], [0, 0, 0, 1]))
        for arm in ("left", "right"):
            length = rng.uniform(0.1, 0.18)
            scene.attach(f"{arm}_object", Cylinder(0.035, length), f"{arm}_tcp", ([0, 0, length / 2], [0, 0, 0, 1]))
    elif family == "cubby":  # a 2 x 2 grid of open cells
        x, z, depth, width, tall = rng.uniform(0.5, 0.6), rng.uniform(-0.45, -0.35), 0.3, 0.8, 0.5
        for k, dz in enumerate((0.0, tall / 2, tall)):
            _board(scene, f"cubby_board{k}", (depth, width, 0.02), (x, 0.0, z + dz))
        for k, y in enumerate((-width / 2, 0.0, width / 2)):
            _board(scene, f"cubby_side{k}", (depth, 0.02, tall), (x, y, z + tall / 2))
        _board(scene, "cubby_back", (0.02, width, tall), (x + depth / 2, 0.0, z + tall / 2))


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


def _held_arm_clear(robot: taplan.Robot, world: CollisionWorld, arms: tuple[str, ...]) -> bool:
    """Whether the arm that does not move (held at home) and what it carries keep ``1.5 MARGIN`` from everything."""
    held = [g for g in robot.groups if g not in arms]
    names = {b.name for b in world.bodies if b.group in held}
    names |= {name for name in world.scene.attached if any(name.startswith(g) for g in held)}
    d = world.distances(robot.home, jacobian=False)
    return all(dist >= MARGIN * 1.5 for (a, b), dist in zip(d.pairs, d.distance, strict=True) if {a, b} & names)


def problems(count: int, seed: int = 0, families: tuple[str, ...] = FAMILIES) -> list[Problem]:
    """``count`` problems spread over ``families`` in turn (seeded; the same seed and families give the same
    problems)."""
    robot = taplan.Robot.teleavatar()
    rng = np.random.default_rng(seed)
    out: list[Problem] = []
    while len(out) < count:
        family = families[len(out) % len(families)]  # every family in turn (a failed draw retries it)
        scene = make_scene(family, rng)
        world = CollisionWorld(robot, scene)
        arms = (("left",), ("right",), ("left", "right"))[int(rng.integers(3))]
        if not _held_arm_clear(robot, world, arms):
            arms = ("left", "right")  # the other arm at home is in the obstacle (a wall across the workspace)
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
