"""Collision-free motion in a scene: goal IK, a joint-space path, jerk-limited timing, and certified verification.

``plan_motion(robot, start, goal, scene)``:

1. **Validate**: start (and a joint goal) within the limits and at least ``margin`` from every obstacle and from the
   robot itself, else :class:`~taplan.errors.CollisionError` naming the pair and the depth in mm.
2. **Goal IK** (pose goals ``{frame: T_root_frame}``): :func:`~taplan.ik.solve_pose` from the start, the home
   configuration and seeded random configurations; solutions closer than ``margin`` to anything are rejected and
   the one closest to the start (joint space) wins. None: :class:`~taplan.errors.PlanningError` naming the target.
3. **Path**, the first of ``stages`` that finds one: the straight joint-space segment when it is certified free
   (``"straight"``); sequential convex optimisation (:mod:`~taplan.planning.optimize`, TrajOpt-style) from the
   straight line, then from polylines through perturbed midpoints (``"optimization"``); RRT-Connect
   (:mod:`~taplan.planning.rrt`) with shortcutting, then the optimiser as its smoother (``"rrt-connect"``). Every
   edge keeps at least ``margin / 2`` by conservative advancement (:mod:`~taplan.planning.verify`).
4. **Timing**: a straight segment gets the time-optimal jerk-limited motion along it
   (:func:`~taplan.timing.straight.straight_line`, ruckig); a polyline :func:`~taplan.timing.jerk_limited`
   (densified so that its spline stays near the segments), interior corners cut by at most ``max_deviation``.
5. **Verification**: the timed trajectory is certified at every instant (conservative advancement with the exact
   peak joint speeds), never only at waypoints. If it comes closer than ``margin / 4``, the path is densified and
   retimed (with exact waypoints at the last attempt); a plan that fails is never returned: PlanningError.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from taplan.errors import InvalidInputError, PlanningError, TimingError
from taplan.limits import JointLimits
from taplan.planning.optimize import optimize_path
from taplan.planning.rrt import rrt_connect, shortcut
from taplan.planning.verify import check_segment, verify_trajectory
from taplan.robot import Robot
from taplan.scene.scene import Scene
from taplan.scene.world import CollisionWorld
from taplan.trajectory import Trajectory

__all__ = ["plan_motion", "MotionPlan", "PlanReport"]

DEFAULT_MARGIN = 0.01  # [m] clearance of the path's configurations (edges keep half, the timed trajectory a quarter)
STAGES = ("straight", "optimization", "rrt-connect")
PERTURBED_SEEDS = 2  # optimisation seeds through a random collision-free midpoint, after the straight line
DENSIFY_STEP = 0.1  # [rad] longest path segment handed to the timing (max-norm)


@dataclass(frozen=True)
class PlanReport:
    """How a plan was made.

    Attributes:
        success: True (a failure raises PlanningError).
        stage: What found the path: ``"straight"`` (the segment is free), ``"optimization"`` (sequential convex
            programming from the straight line or a perturbed seed) or ``"rrt-connect"`` (sampling).
        stage_times: Seconds per stage (``validate``, ``goal_ik``, ``straight``, ``optimize``, ``sample``,
            ``smooth``, ``timing``, ``verify``; 0 for a stage that did not run).
        path_length: Joint-space length of the path [rad] (sum of Euclidean segment lengths).
        duration: Trajectory duration [s].
        min_clearance: Smallest clearance along the timed trajectory [m] (at the verification's evaluations).
        min_clearance_pair: Where it occurs.
        waypoints: Waypoints of the geometric path before densifying.
        timing_attempts: Timings tried until one was verified.
        goal: The goal configuration [rad] (the IK solution for a pose goal).
        smoothed: True when the sampled path was shortened by the optimiser (stage ``"rrt-connect"``).
    """

    success: bool
    stage: str
    stage_times: dict[str, float]
    path_length: float
    duration: float
    min_clearance: float
    min_clearance_pair: tuple[str, str]
    waypoints: int
    timing_attempts: int
    goal: np.ndarray = field(repr=False)
    smoothed: bool = False


@dataclass(frozen=True)
class MotionPlan:
    """A verified plan: ``trajectory`` (all the robot's joints, model order), the geometric ``path`` (K, nq) and the
    ``report``."""

    trajectory: Trajectory
    path: np.ndarray
    report: PlanReport


def _densify(path: list[np.ndarray], step: float) -> np.ndarray:
    out = [path[0]]
    for a, b in zip(path[:-1], path[1:], strict=True):
        pieces = max(1, int(np.ceil(np.abs(b - a).max() / step)))
        out += [a + (b - a) * k / pieces for k in range(1, pieces + 1)]
    return np.array(out)


def _find_path(
    world: CollisionWorld,
    q0: np.ndarray,
    q1: np.ndarray,
    active: np.ndarray,
    limits: JointLimits,
    margin: float,
    stages: tuple[str, ...],
    max_time: float,
    rng: np.random.Generator,
    times: dict[str, float],
) -> tuple[str, list[np.ndarray], bool]:
    """(stage, path, smoothed): the first stage in ``stages`` that finds a certified path."""
    deadline = time.perf_counter() + max_time
    for key in ("straight", "optimize", "sample", "smooth"):
        times[key] = 0.0
    for stage in stages:
        clock = time.perf_counter()
        if stage == "straight":
            found = check_segment(world, q0, q1, margin).valid
            times["straight"] += time.perf_counter() - clock
            if found:
                return stage, [q0, q1], False
        elif stage == "optimization":
            for seed_path in _optimization_seeds(world, q0, q1, active, limits, margin, rng):
                result = optimize_path(world, seed_path, active, limits.lower, limits.upper, margin, deadline=deadline)
                if result is not None:
                    times["optimize"] += time.perf_counter() - clock
                    return stage, list(result.path), False
                if time.perf_counter() >= deadline:
                    break
            times["optimize"] += time.perf_counter() - clock
        else:
            remaining = max(deadline - time.perf_counter(), 0.0)
            found_path = rrt_connect(
                world, q0, q1, active, limits.lower, limits.upper, margin, max_time=remaining, rng=rng
            )
            if found_path is None:
                times["sample"] += time.perf_counter() - clock
                break
            path = shortcut(world, found_path, margin, rng=rng)
            times["sample"] += time.perf_counter() - clock
            clock = time.perf_counter()
            smooth = optimize_path(world, np.array(path), active, limits.lower, limits.upper, margin, max_iterations=15)
            times["smooth"] += time.perf_counter() - clock
            if smooth is not None and _length(smooth.path) < _length(np.array(path)):
                return stage, list(smooth.path), True
            return stage, path, False
    raise PlanningError(f"no collision-free path found within {max_time:g} s (stages: {', '.join(stages)})")


def _length(path: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def _optimization_seeds(
    world: CollisionWorld,
    q0: np.ndarray,
    q1: np.ndarray,
    active: np.ndarray,
    limits: JointLimits,
    margin: float,
    rng: np.random.Generator,
) -> list[np.ndarray]:
    """The straight line, then polylines through random collision-free configurations near its middle."""
    seeds = [np.array([q0, q1])]
    spread = 0.5 * np.maximum(np.abs(q1 - q0)[active], 0.3)  # [rad]
    for _ in range(PERTURBED_SEEDS):
        for _attempt in range(20):
            middle = (q0 + q1) / 2
            middle[active] += rng.uniform(-1.0, 1.0, active.size) * spread
            middle = np.clip(middle, limits.lower, limits.upper)
            if world.min_distance(middle)[0] >= margin:
                seeds.append(np.array([q0, middle, q1]))
                break
    return seeds


def _goal_ik(
    robot: Robot,
    world: CollisionWorld,
    targets: Mapping[str, Any],
    start: np.ndarray,
    limits: JointLimits,
    margin: float,
    seeds: int,
    rng: np.random.Generator,
) -> np.ndarray:
    from taplan.ik.solve_pose import solve_pose

    lower, upper = limits.lower, limits.upper
    candidates = [start, robot.home] + [lower + rng.uniform(0, 1, robot.nq) * (upper - lower) for _ in range(seeds)]
    best, best_cost = None, np.inf
    reason = "no IK solution within 1 mm / 0.01 rad"
    for k, seed_q in enumerate(candidates):
        seed_q = np.where(np.isin(np.arange(robot.nq), _moving_joints(robot, targets)), seed_q, start)
        result = solve_pose(robot, targets, seed_q, limits=limits, restarts=2, seed=k)
        if not result.success:
            continue
        d, pair = world.min_distance(result.q)
        if d < margin:
            reason = f"IK solutions collide ({pair[0]} / {pair[1]}: {d * 1e3:.1f} mm, {margin * 1e3:.1f} mm needed)"
            continue
        cost = float(np.linalg.norm(result.q - start))
        if cost < best_cost:
            best, best_cost = result.q, cost
        if best is not None and k >= 2:
            break  # the start and home seeds were tried; a collision-free solution near the start is enough
    if best is None:
        raise PlanningError(f"goal {sorted(targets)}: unreachable without collision ({reason})")
    return best


def _moving_joints(robot: Robot, targets: Mapping[str, Any]) -> np.ndarray:
    """Indices of the joints that move the target frames (their arm groups)."""
    moving: list[int] = []
    for frame in targets:
        for group in robot.groups.values():
            if frame == group.ee_frame or frame.startswith(group.name):
                moving += list(group.indices)
    return np.array(sorted(set(moving)) or range(robot.nq), dtype=int)


def _full_trajectory(part: Trajectory, names: tuple[str, ...], index: np.ndarray, hold: np.ndarray) -> Trajectory:
    c = part.coefficients
    full = np.zeros((c.shape[0], c.shape[1], len(names)))
    full[:, 0, :] = hold
    full[:, :, index] = c
    return Trajectory.from_polynomials(part.times, full, names)


def plan_motion(
    robot: Robot,
    start: npt.ArrayLike,
    goal: npt.ArrayLike | Mapping[str, Any],
    scene: Scene | None = None,
    limits: JointLimits | None = None,
    *,
    world: CollisionWorld | None = None,
    margin: float = DEFAULT_MARGIN,
    max_deviation: float = 0.05,
    max_time: float = 10.0,
    stages: tuple[str, ...] = STAGES,
    ik_seeds: int = 6,
    seed: int = 0,
) -> MotionPlan:
    """A jerk-limited, collision-free trajectory from ``start`` to ``goal`` around ``scene``.

    Args:
        robot: The robot.
        start: Start configuration [rad] (nq,).
        goal: Goal configuration [rad] (nq,), or pose targets ``{frame: T_root_frame}`` for one or both hands.
        scene: Obstacles (None: the robot's self-collision only).
        limits: Joint limits (default ``robot.planning_limits``).
        world: A ready :class:`~taplan.scene.CollisionWorld` (its scene is used instead of ``scene``).
        margin: Clearance [m] of the path's configurations; the timed trajectory is certified to keep a quarter.
        max_deviation: Largest corner cut of the jerk-limited timing at interior waypoints [rad] (the first timing;
            when its verification fails the retries cut a fifth of it, then follow the waypoints exactly).
        max_time: Time budget of the path search (optimisation and sampling) [s].
        stages: Path stages to try, in this order: any of ``"straight"``, ``"optimization"``, ``"rrt-connect"``.
        ik_seeds: Random seeds of the goal IK beyond the start and home.
        seed: Seed of every random choice (reproducible plans).

    Returns:
        The verified plan.

    Raises:
        InvalidInputError: malformed start or goal (shape, NaN, outside the limits).
        CollisionError: start or goal in collision (names the pair and the depth in mm).
        PlanningError: unreachable goal pose, no path within ``max_time``, or no timing that verifies.
    """
    times: dict[str, float] = {}
    clock = time.perf_counter()
    limits = robot.planning_limits if limits is None else limits
    if not isinstance(limits, JointLimits) or limits.names != robot.joint_names:
        raise InvalidInputError("limits", limits, f"JointLimits over the robot's joints {robot.joint_names}")
    if not (isinstance(margin, (int, float)) and np.isfinite(margin) and margin > 0):
        raise InvalidInputError("margin", margin, "a clearance > 0 [m]")
    if not (isinstance(stages, tuple) and stages and set(stages) <= set(STAGES)):
        raise InvalidInputError("stages", stages, f"a non-empty tuple of {STAGES}")
    world = world if world is not None else CollisionWorld(robot, scene)
    q0 = robot.check_configuration(start, "start")
    if not limits.within(q0):
        raise InvalidInputError("start", np.round(q0, 4).tolist(), "a configuration within the limits")
    world.check_configuration(q0, "start", margin=margin)
    rng = np.random.default_rng(seed)
    times["validate"] = time.perf_counter() - clock

    clock = time.perf_counter()
    if isinstance(goal, Mapping):
        q1 = _goal_ik(robot, world, goal, q0, limits, margin, ik_seeds, rng)
    else:
        q1 = robot.check_configuration(goal, "goal")
        if not limits.within(q1):
            raise InvalidInputError("goal", np.round(q1, 4).tolist(), "a configuration within the limits")
        world.check_configuration(q1, "goal", margin=margin)
    times["goal_ik"] = time.perf_counter() - clock

    active = np.flatnonzero(np.abs(q1 - q0) > 1e-12)
    if active.size == 0:
        raise InvalidInputError("goal", "the start configuration", "a goal that differs from the start")
    stage, path, smoothed = _find_path(world, q0, q1, active, limits, margin, stages, max_time, rng, times)

    from taplan.timing.jerk_limited import jerk_limited
    from taplan.timing.straight import straight_line

    sub = limits.subset([robot.joint_names[i] for i in active])
    timing_time = verify_time = 0.0
    trajectory = verification = None
    timing_error: TimingError | None = None
    attempts = 0
    # a straight segment gets ruckig's time-optimal jerk-limited motion on it; polylines the filtered TOPP-RA,
    # denser and finally through the exact waypoints when the verification asks for more accuracy
    plans: list[tuple[float, float] | None] = [None] if len(path) == 2 else []
    plans += [(DENSIFY_STEP, max_deviation), (DENSIFY_STEP / 2, max_deviation / 5), (DENSIFY_STEP / 4, 0.0)]
    for attempt, plan in enumerate(plans):
        attempts = attempt + 1
        clock = time.perf_counter()
        try:
            if plan is None:
                part = straight_line(path[0][active], path[1][active], sub)
            else:
                step, deviation = plan
                dense = _densify(path, step)[:, active]
                if deviation > 0:
                    part = jerk_limited(dense, sub, method="joint", max_deviation=deviation).trajectory
                else:
                    part = jerk_limited(dense, sub, method="path").trajectory
        except TimingError as exc:
            timing_error = exc
            timing_time += time.perf_counter() - clock
            continue  # a denser path stays closer to its segments
        trajectory = _full_trajectory(part, robot.joint_names, active, q0)
        timing_time += time.perf_counter() - clock
        clock = time.perf_counter()
        verification = verify_trajectory(world, trajectory, floor=margin / 4, hold=q0)
        verify_time += time.perf_counter() - clock
        if verification.collision_free:
            break
    times["timing"] = timing_time
    times["verify"] = verify_time
    if trajectory is None or verification is None:
        raise PlanningError(f"timing the path failed: {timing_error}") from timing_error
    if not verification.collision_free:
        pair = verification.pair
        raise PlanningError(
            f"the timed trajectory comes within {verification.min_clearance * 1e3:.1f} mm of collision "
            f"({pair[0]} / {pair[1]} at t = {verification.time:.3f} s) after {attempts} timings: not returned"
        )
    geometric = np.array(path)
    report = PlanReport(
        success=True,
        stage=stage,
        stage_times=times,
        path_length=_length(geometric),
        duration=trajectory.duration,
        min_clearance=verification.min_clearance,
        min_clearance_pair=verification.pair,
        waypoints=len(path),
        timing_attempts=attempts,
        smoothed=smoothed,
        goal=q1,
    )
    return MotionPlan(trajectory, geometric, report)
