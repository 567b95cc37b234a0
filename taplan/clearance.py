"""Clearance of a plan or of a command stream: the robot's own bodies always, a scene's obstacles when given.

This is the collision half of every check taplan makes before motion (``taplan check``, ``taplan plan``,
``taplan run``, :func:`taplan.check.check`, the runner's streamers). It asks the
:class:`~taplan.scene.CollisionWorld` of the robot (its own bodies, whatever :mod:`taplan.scene.robot_bodies`
gives: arm links, chest, head, torso) plus the scene, so a scene *adds* obstacles; it never switches checking on.

* A :class:`~taplan.trajectory.Trajectory` is certified continuously (conservative advancement,
  :func:`taplan.planning.verify_trajectory`): clearance above ``floor`` at every instant, not only at samples.
* A stream of configurations (commands at the arm rate, replay samples) is certified along the straight joint-space
  segments between consecutive samples (:func:`taplan.planning.check_segment`): what the robot's position loop
  interpolates between two commands.

``SELF_CLEARANCE`` (0 m) is the floor for the robot's own bodies: the capsules already enclose the URDF's collision
cylinders (and the chest and head primitives are sized with their own allowance), so touching capsules fail.
Pairs that touch at home (a shoulder on the chest) are allowed pairs of the world and never checked.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from taplan.check import register_collision_check

__all__ = ["ClearanceCheck", "SELF_CLEARANCE", "check_clearance", "robot_world", "teleavatar_world"]

MAX_SAMPLES = 20000  # check(): longer subjects are not certified (notes say so)
MAX_CERTIFIED_DURATION = 3600.0  # [s] longer plans are refused, not certified (0.1 s windows: memory and time)
SELF_CLEARANCE = 0.0  # [m] floor of robot-robot pairs: the capsules already enclose the URDF's collision geometry


@dataclass(frozen=True)
class ClearanceCheck:
    """Outcome of :func:`check_clearance`.

    Attributes:
        passed: The whole subject keeps more than ``floor`` of clearance.
        min_clearance: Smallest clearance seen [m] (negative: penetration depth).
        pair: The pair where it occurs.
        time: When [s] (trajectory time, or the sample's time).
        floor: Required clearance [m].
        bodies: The robot bodies checked.
        self_pairs: How many robot-robot pairs were checked.
        obstacles: How many scene obstacles were checked.
        evaluations: Distance evaluations used.
    """

    passed: bool
    min_clearance: float
    pair: tuple[str, str]
    time: float
    floor: float
    bodies: tuple[str, ...]
    self_pairs: int
    obstacles: int
    evaluations: int

    def line(self) -> str:
        """One line: what was checked and the verdict, e.g. ``collision: 9 bodies ... FAIL: ...``."""
        scope = f"{len(self.bodies)} robot bodies ({', '.join(self.bodies)}), {self.self_pairs} self pairs"
        if self.obstacles:
            scope += f", {self.obstacles} scene obstacles"
        where = f"{self.pair[0]} / {self.pair[1]}" if self.pair[0] else "no pair"
        clearance = f"min clearance {self.min_clearance * 1e3:.1f} mm ({where}) at t = {self.time:.3f} s"
        if self.passed:
            return f"collision: {scope}: {clearance}: ok"
        depth = "in collision" if self.min_clearance <= 0 else f"closer than {self.floor * 1e3:.1f} mm"
        return f"collision: {scope}: FAIL: {where} {depth}, {clearance}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "passed": self.passed,
            "min_clearance": self.min_clearance if math.isfinite(self.min_clearance) else None,
            "pair": list(self.pair),
            "time": self.time,
            "floor": self.floor,
            "bodies": list(self.bodies),
            "self_pairs": self.self_pairs,
            "obstacles": self.obstacles,
        }


@functools.lru_cache(maxsize=1)
def teleavatar_world() -> Any:
    """The bundled TeleAvatar's own bodies (built once per process; no scene)."""
    from taplan.robot import Robot
    from taplan.scene import CollisionWorld

    return CollisionWorld(Robot.teleavatar())


def robot_world(robot: Any = None, scene: Any = None) -> Any:
    """The :class:`~taplan.scene.CollisionWorld` of ``robot`` (default the bundled TeleAvatar) and ``scene``."""
    from taplan.scene import CollisionWorld

    if isinstance(robot, CollisionWorld):
        return robot
    if robot is None and scene is None:
        return teleavatar_world()
    if robot is None:
        robot = teleavatar_world().robot
    return CollisionWorld(robot, scene)


def check_clearance(
    subject: Any,
    world: Any = None,
    *,
    joint_names: tuple[str, ...] | None = None,
    times: npt.ArrayLike | None = None,
    hold: npt.ArrayLike | None = None,
    floor: float = SELF_CLEARANCE,
) -> ClearanceCheck:
    """Check a plan or a stream against the robot's own bodies and the world's obstacles.

    Args:
        subject: A :class:`~taplan.trajectory.Trajectory`, or configurations (k, n) of the joints ``joint_names``
            (default every robot joint in model order) sampled at ``times`` [s].
        world: A :class:`~taplan.scene.CollisionWorld` (default the TeleAvatar's own bodies), or a
            :class:`~taplan.robot.Robot` (its own bodies).
        joint_names: Names of the columns of a configuration array.
        times: Sample times [s] of a configuration array (default 0, 1, 2, ...).
        hold: Positions [rad] (nq,) of the joints the subject does not drive (default the robot's home).
        floor: Required clearance [m].
    """
    from taplan.planning.verify import check_segment, verify_trajectory
    from taplan.trajectory import Trajectory

    world = robot_world(world)
    robot = world.robot
    base = robot.home.copy() if hold is None else np.asarray(hold, dtype=float).copy()
    bodies = tuple(b.name for b in world.bodies)
    obstacles = len(world.scene.obstacles) if hasattr(world.scene, "obstacles") else 0

    def result(passed: bool, lowest: float, pair: tuple[str, str], when: float, evaluations: int) -> ClearanceCheck:
        pairs = len(world.self_pairs)
        found = (float(lowest), pair, float(when), float(floor))
        return ClearanceCheck(passed, *found, bodies, pairs, obstacles, evaluations)

    if isinstance(subject, Trajectory):
        duration = float(subject.times[-1] - subject.times[0])
        if not (math.isfinite(duration) and duration <= MAX_CERTIFIED_DURATION):
            from taplan.errors import InvalidInputError

            raise InvalidInputError(
                "trajectory", f"{duration:g} s", f"at most {MAX_CERTIFIED_DURATION:g} s to certify its clearance"
            )
        v = verify_trajectory(world, subject, floor=floor, hold=base)
        return result(v.collision_free, v.min_clearance, v.pair, v.time, v.evaluations)
    q = np.asarray(subject, dtype=float)
    names = robot.joint_names if joint_names is None else tuple(joint_names)
    if q.ndim != 2 or q.shape[1] != len(names) or q.shape[0] < 1:
        from taplan.errors import InvalidInputError

        raise InvalidInputError("configurations", f"shape {q.shape}", f"(k >= 1, {len(names)})")
    t = np.arange(len(q), dtype=float) if times is None else np.asarray(times, dtype=float)
    configurations = np.repeat(base[None, :], len(q), axis=0)
    configurations[:, robot.indices(names)] = q
    lowest, pair, when, evaluations = math.inf, ("", ""), float(t[0]), 0
    d, p = world.min_distance(configurations[0])
    evaluations += 1
    lowest, pair = d, p
    if d <= floor:
        return result(False, lowest, pair, when, evaluations)
    for k in range(len(configurations) - 1):
        a, b = configurations[k], configurations[k + 1]
        if np.array_equal(a, b):
            continue
        seg = check_segment(world, a, b, margin=2 * floor, points=floor)
        evaluations += seg.evaluations
        if seg.clearance < lowest:
            lowest, pair, when = seg.clearance, seg.pair, float(t[k])
        if not seg.valid:
            return result(False, lowest, pair, float(t[k]), evaluations)
    return result(True, lowest, pair, when, evaluations)


def _for_check(
    subject: Any,
    names: tuple[str, ...],
    q: np.ndarray,
    t: np.ndarray,
    clearance: Any,
    hold: Any,
    notes: list[str],
) -> ClearanceCheck | None:
    """The collision half of :func:`taplan.check.check` (``clearance="auto"``: the TeleAvatar's own bodies when
    every joint is one of its joints; a Robot or a CollisionWorld as given)."""
    from taplan.trajectory import Trajectory

    if isinstance(clearance, str) and clearance == "auto":
        world = teleavatar_world()
        if not set(names) <= set(world.robot.joint_names):
            notes.append("collision: not checked (the joints are not the TeleAvatar's; pass clearance=robot)")
            return None
        clearance = world
    robot = clearance.robot if hasattr(clearance, "robot") else clearance
    index = robot.indices(names)
    lower, upper = robot.limits.lower[index] - 0.5, robot.limits.upper[index] + 0.5
    if q.size and (not np.all(np.isfinite(q)) or np.any(q < lower) or np.any(q > upper) or len(q) > MAX_SAMPLES):
        # far outside the limits (the limit check fails it) or too long to certify here: no certificate
        notes.append("collision: not checked (positions far outside the limits, or more than 20000 samples)")
        return None
    if isinstance(subject, Trajectory):
        return check_clearance(subject, clearance, hold=hold)
    return check_clearance(q, clearance, joint_names=names, times=t, hold=hold)


register_collision_check(_for_check)
