"""Collision-free motion in a scene: goal IK, a joint-space path, jerk-limited timing, and certified verification.

``plan_motion(robot, start, goal, scene)``:

1. **Validate**: start (and a joint goal) within the limits and at least ``floor`` (2.5 mm) from every obstacle and
   from the robot itself, else :class:`~taplan.errors.CollisionError` naming the pair and the distance in mm. An end
   closer than ``margin`` is left or approached along a short certified segment (:mod:`~taplan.planning.ends`).
2. **Goal IK** (pose goals ``{frame: T_root_frame}``): :func:`~taplan.ik.solve_pose` from the start, the home
   configuration and seeded random configurations; solutions closer than ``floor`` are rejected. The start seed's
   solution wins when it is clear of ``margin`` (IK from the start converges to a solution near it: one solve
   instead of three); else the one closest to the start (joint space) among those clear of ``margin`` (else among
   those clear of ``floor``). One short attempt per seed first; restarts only when every seed failed
   (``GOAL_IK_ITERATIONS``, ``GOAL_IK_SEEDS``, ``GOAL_IK_RESTARTS``).
   None: :class:`~taplan.errors.PlanningError` naming the target.
3. **Path**, the first of ``stages`` that finds one: the straight joint-space segment when it is certified free
   (``"straight"``); sequential convex optimisation (:mod:`~taplan.planning.optimize`, TrajOpt-style) from the
   straight line, then from polylines through perturbed midpoints (``"optimization"``; the straight line only, for
   a quarter of the search time and ``OPTIMIZE_ITERATIONS`` QPs, when the sampler follows, and given up when it
   stalls in collision: :data:`~taplan.planning.optimize.STALL_WINDOW`, or is still deep in it after
   :data:`~taplan.planning.optimize.STALL_BUDGET` of CPU); RRT-Connect
   (:mod:`~taplan.planning.rrt`, exploring with a compiled clearance test; when both arms move, first one arm
   after the other) with shortcutting, then smoothed with the same test (the arms moved together, shortcuts along
   the path, corners blended), resampled evenly and certified again (``"rrt-connect"``); in
   a passage too narrow for the margin the sampler's margin shrinks to half, then to the floor
   (``report.margin``). Every edge keeps at least half its margin by conservative advancement
   (:mod:`~taplan.planning.verify`).
4. **Timing**: a straight segment gets the time-optimal jerk-limited motion along it
   (:func:`~taplan.timing.straight.straight_line`, ruckig); a polyline :func:`~taplan.timing.jerk_limited`
   (densified so that its spline stays near the segments), interior corners cut by at most ``max_deviation``.
5. **Verification**: the timed trajectory is certified at every instant (conservative advancement with bounds
   of the joint speeds), never only at waypoints. If the first (fastest) timing comes closer than ``margin / 4``, the
   other timings (half the limits, corners cut less on a denser path, a quarter of the limits, exact waypoints) are
   computed and verified shortest first, so the fallback is the fastest safe one, and ``report.timing_fallback``
   says which and why; a plan that fails is never returned: PlanningError.

``max_time`` bounds the whole call: the goal IK stops seeding after half of it, the path search leaves
``FINISH_SHARE`` of it (0.05–2 s) for timing and verification, a sampled path is smoothed in ``SMOOTH_SHARE`` of
the time left and its fastest timing verified in half of what then remains (else the certified unsmoothed path,
with its fallback timings and a note), and every
stage checks the deadline between its indivisible steps: the call ends within ``max_time + BUDGET_TOLERANCE``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from taplan._threads import run_single_threaded
from taplan.errors import CollisionError, InvalidInputError, PlanningError, TaplanError, TimingError
from taplan.limits import JointLimits
from taplan.planning.compiled_check import ClearanceCheck
from taplan.planning.ends import DEFAULT_FLOOR, Approach, approach_segment
from taplan.planning.kernels_ready import load_compiled_kernels
from taplan.planning.optimize import optimize_path, resample
from taplan.planning.rrt import (
    SMOOTH_SPACING_SHARE,
    certify_path,
    rrt_connect_groups,
    rrt_connect_shrinking,
    smooth_path,
)
from taplan.planning.verify import MIN_CERTIFIED, SegmentCheck, Verification, check_segment, verify_trajectory
from taplan.robot import Robot
from taplan.scene.scene import Scene, as_pose
from taplan.scene.world import CollisionWorld
from taplan.trajectory import Trajectory

__all__ = ["plan_motion", "MotionPlan", "PlanReport"]

DEFAULT_MARGIN = 0.01  # [m] clearance of the path's configurations (edges keep half, the timed trajectory a quarter)
STAGES = ("straight", "optimization", "rrt-connect")
PERTURBED_SEEDS = 2  # optimisation seeds through a random collision-free midpoint, after the straight line
DENSIFY_STEP = 0.1  # [rad] longest path segment handed to the timing (max-norm)
SMOOTH_STEP = 0.1  # [rad] waypoint spacing (Euclidean) of a smoothed sampled path
# TOPP-RA grid segments per densified interval of a polyline's timing: 4 instead of toppra_retime's 16 is 2-5x
# cheaper (15-50 ms instead of 50-110 ms CPU per optimised path; a sampled path whose corners need the exact-waypoint
# filter, several TOPP-RA solves: 0.7 s instead of 2.2 s) for durations 0-6 % longer (issue 22's profile)
TIMING_POINTS = 4
# ... and at least this many grid segments in all (toppra_retime's default 128 gave the 12-22 waypoint paths of the
# optimiser 5-8 segments per interval: 64 lets them have 4, TOPP-RA and everything after it on a third fewer pieces;
# the 20 optimised paths of the benchmark: median duration 1.491 -> 1.484 s, one 4 % shorter, four 0.07-0.8 % longer)
TIMING_MIN_GRID = 64
BUDGET_TOLERANCE = 0.2  # [s] documented overrun of max_time: one indivisible step (an IK solve, a QP, a timing)
IK_SHARE = 0.5  # the goal IK stops trying seeds after this share of the budget
# The goal IK's first round: one attempt per seed (no restarts inside solve_pose), stopped after this many iterations
# (converging attempts take 3-15; a stuck one ran 100: 24 ms), and ended once a clear solution is in hand and this
# many seeds were tried (start, home, one random). Only when no seed gave a solution, a second round gives every
# seed GOAL_IK_RESTARTS restarts and the full iterations (what every seed got before: divider goals 30-60 -> 6-13 ms).
GOAL_IK_ITERATIONS, GOAL_IK_SEEDS, GOAL_IK_RESTARTS = 30, 3, 2
FINISH_SHARE, FINISH_MIN, FINISH_MAX = 0.35, 0.05, 2.0  # [-, s, s] the path search leaves this for timing + verify
SMOOTH_SHARE, SMOOTH_MIN = 0.5, 0.05  # [-, s] a sampled path's smoothing gets this share of the time left, if >= 0.05 s
OPTIMIZE_SHARE = 0.25  # of the search time, for the optimiser from the straight line when the sampler follows it
# QPs of that optimiser: a load-independent bound on a stuck one (on the 39 + 80 benchmark problems it solved all
# but 3-4 of those it solves at all within 15; the sampled route takes 0.2-0.8 s CPU). A tighter bound (8), and
# skipping the optimiser when 45 % of the straight segment is blocked, were measured after the optimiser's
# speed-ups of this session: the same CPU p95 (615-637 ms on the hard set) with longer durations (24 problems
# sampled with or without it: 40.2 s -> 44.7 s in all), so neither is used
OPTIMIZE_ITERATIONS = 15
MARGIN_SHARES = 0.7  # of the time left, for the sampler at each margin but the last (the floor gets the rest)
GROUPS_SHARE = 0.5  # of the sampler's time, for one arm after the other when both move (then both at once)


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
        smoothed: True when the plan follows the smoothed sampled path (stage ``"rrt-connect"``).
        approaches: The bent ends: a start or goal closer than the margin (but clear of the floor) is left or
            approached along a short certified segment (:class:`~taplan.planning.ends.Approach`: where, how close,
            what is certified).
        margin: The clearance the path keeps at its configurations [m]: ``margin``, or less when only the sampler
            found a path, at a lower clearance, through a narrow passage (at least the floor; ``notes`` says so).
        notes: What the planner gave up: the smoothing of a sampled path to hold the time budget, the margin in a
            narrow passage, or (for safety) the fastest timing (see ``timing_fallback``).
        timing_fallback: Empty when the fastest timing verified; else which slower timing was used and why (the
            fastest cut a corner into the margin), e.g. ``"timing fell back to ... at 0.5 x the limits: 0.77 s"``.
        elapsed: Wall time of the whole call [s].
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
    approaches: tuple[Approach, ...] = ()
    margin: float = DEFAULT_MARGIN
    notes: tuple[str, ...] = ()
    elapsed: float = 0.0
    timing_fallback: str = ""


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


def _margins(margin: float, floor: float) -> tuple[float, ...]:
    """The sampler's clearances, widest first: the path margin, then halfway to the floor, then the floor."""
    out = [margin]
    for m in (max(margin / 2, floor), floor):
        if m < out[-1] - 1e-9:
            out.append(m)
    return tuple(out)


def _find_path(
    world: CollisionWorld,
    q0: np.ndarray,
    q1: np.ndarray,
    active: np.ndarray,
    limits: JointLimits,
    margin: float,
    floor: float,
    stages: tuple[str, ...],
    deadline: float,
    rng: np.random.Generator,
    times: dict[str, float],
    certify: bool = True,
) -> tuple[str, list[np.ndarray], SegmentCheck | None, float] | None:
    """(stage, path, the straight segment's certificate or None, the margin the path keeps): the first stage in
    ``stages`` that finds a certified path before ``deadline`` (``time.perf_counter()``), else None; a sampled path
    is shortcut but not yet smoothed, and without ``certify`` not yet certified (the caller certifies the smoothed
    path, and this one only when the smoothed one is not used).

    The optimiser gets ``OPTIMIZE_SHARE`` of the search time when the sampler follows it. The sampler tries the
    margins of :func:`_margins` in turn (``MARGIN_SHARES`` of the time left each, the floor all that remains): a
    passage narrower than the arm plus twice the margin is crossed with less clearance rather than not at all. When
    both arms move, the sampler first moves one arm after the other (``GROUPS_SHARE`` of its time, both orders:
    two 7-joint searches), then both at once."""
    for index, stage in enumerate(stages):
        clock = time.perf_counter()
        if stage == "straight":
            certificate = check_segment(world, q0, q1, margin)
            times["straight"] += time.perf_counter() - clock
            if certificate.valid:
                return stage, [q0, q1], certificate, margin
        elif stage == "optimization":
            cap, perturbed, iterations, sampler_follows = deadline, PERTURBED_SEEDS, 30, False
            # perceived occupancy: the optimiser gets the whole search. Re-measured with the sampler's occupancy test
            # (FieldClearance) on the first 20 benchmark scans (before give_up_stalled): 19 the same stage and CPU
            # within noise either way; window #18: capped, the optimiser failed and the sampler needed 12.9 s CPU,
            # uncapped it planned in 5.6 s
            compiled = not any(hasattr(o.shape, "capsule_distances") for o in world.scene.obstacles.values())
            if "rrt-connect" in stages[index + 1 :] and compiled:
                # the sampler's path through the passage (smoothed later) is a better second seed than a random
                # midpoint: the straight line only, for a share of the time and OPTIMIZE_ITERATIONS QPs
                cap, perturbed = clock + OPTIMIZE_SHARE * max(deadline - clock, 0.0), 0
                iterations, sampler_follows = OPTIMIZE_ITERATIONS, True
            for seed_path in _optimization_seeds(world, q0, q1, active, limits, margin, perturbed, rng):
                if time.perf_counter() >= cap:
                    break
                result = optimize_path(
                    world,
                    seed_path,
                    active,
                    limits.lower,
                    limits.upper,
                    margin,
                    max_iterations=iterations,
                    deadline=cap,
                    give_up_stalled=sampler_follows,  # stuck in collision: the sampler's turn
                )
                if result is not None:
                    times["optimize"] += time.perf_counter() - clock
                    return stage, list(result.path), None, margin
            times["optimize"] += time.perf_counter() - clock
        else:
            margins = _margins(margin, floor)
            shares = (MARGIN_SHARES,) * (len(margins) - 1)
            bounds = (limits.lower, limits.upper, margins)
            options: dict[str, Any] = {"shares": shares, "rng": rng, "certify": certify}  # the same for both searches
            groups = [np.intersect1d(g.indices, active) for g in world.robot.groups.values()]
            groups = [g for g in groups if g.size]
            sampled = None
            if len(groups) > 1 and sum(g.size for g in groups) == active.size:  # both arms: one, then the other
                left = GROUPS_SHARE * max(deadline - time.perf_counter(), 0.0)
                sampled = rrt_connect_groups(world, q0, q1, groups, *bounds, max_time=left, **options)
            if sampled is None:
                left = max(deadline - time.perf_counter(), 0.0)
                sampled = rrt_connect_shrinking(world, q0, q1, active, *bounds, max_time=left, **options)
            if sampled is not None:
                times["sample"] += time.perf_counter() - clock
                return stage, sampled[0], None, sampled[1]
            times["sample"] += time.perf_counter() - clock
    return None


def _smooth_sampled(
    world: CollisionWorld,
    path: list[np.ndarray],
    active: np.ndarray,
    margin: float,
    rng: np.random.Generator,
    deadline: float,
) -> list[np.ndarray] | None:
    """The sampled ``path`` smoothed with the sampler's compiled test (:func:`~taplan.planning.rrt.smooth_path`:
    the arms synchronised, shortcuts, corners blended), resampled to evenly spaced waypoints (the timing's spline
    has uniform knots: uneven waypoints make it swerve and slow down) and certified edge by edge to keep
    ``margin / 2``; None when that does not finish before ``deadline``."""
    groups = [np.intersect1d(g.indices, active) for g in world.robot.groups.values()]
    check = ClearanceCheck(world, margin, active)
    smooth = smooth_path(
        lambda a, b: check.motion(a, b, SMOOTH_SPACING_SHARE * margin),
        path,
        active,
        [g for g in groups if g.size],
        rng=rng,
        deadline=deadline,
    )
    geometric = np.array(smooth)
    count = max(2, int(np.ceil(_length(geometric) / SMOOTH_STEP)) + 1)
    even = list(resample(geometric, count))
    if not all(check(q) for q in even[1:-1]):  # the waypoints keep the margin, like every planner path's
        return None
    return certify_path(world, even, margin, deadline)


def _length(path: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def _optimization_seeds(
    world: CollisionWorld,
    q0: np.ndarray,
    q1: np.ndarray,
    active: np.ndarray,
    limits: JointLimits,
    margin: float,
    perturbed: int,
    rng: np.random.Generator,
) -> list[np.ndarray]:
    """The straight line, then ``perturbed`` polylines through random collision-free configurations near its
    middle."""
    seeds = [np.array([q0, q1])]
    spread = 0.5 * np.maximum(np.abs(q1 - q0)[active], 0.3)  # [rad]
    for _ in range(perturbed):
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
    floor: float,
    seeds: int,
    rng: np.random.Generator,
    deadline: float,
) -> np.ndarray:
    """The start seed's goal IK solution when it is at least ``margin`` from everything, else the one closest to the
    start among those at least ``margin`` away, else among those at least ``floor`` that a certified segment
    approaches (:func:`~taplan.planning.ends.approach_segment`: the plan needs one); seeds stop at ``deadline``. A
    first round gives each seed one short attempt and ends once ``GOAL_IK_SEEDS`` seeds were tried and one gave a
    clear solution; a second round (only when the first gave no usable one) gives each seed ``GOAL_IK_RESTARTS``
    random restarts."""
    from taplan.ik.solve_pose import solve_pose

    lower, upper = limits.lower, limits.upper
    candidates = [start, robot.home] + [lower + rng.uniform(0, 1, robot.nq) * (upper - lower) for _ in range(seeds)]
    clear_best: np.ndarray | None = None
    clear_cost = np.inf
    near: list[tuple[float, np.ndarray]] = []  # solutions clear of the floor only: (distance to start, q)
    approached: np.ndarray | None = None
    reason = "no IK solution within 1 mm / 0.01 rad"
    closest = (np.inf, np.inf)  # the best failed IK's position [m] and orientation [rad] error
    moving = np.isin(np.arange(robot.nq), _moving_joints(robot, targets))
    rounds = ((0, GOAL_IK_ITERATIONS), (GOAL_IK_RESTARTS, 100))  # (restarts, iterations per attempt)
    for restarts, iterations in rounds:
        for k, seed_q in enumerate(candidates):
            if clear_best is not None and k >= GOAL_IK_SEEDS:
                break  # warm start: a clear solution, and the start, home and a random seed were tried
            if time.perf_counter() >= deadline:
                reason = f"the goal IK's share of the time budget ran out after {k} seeds"
                break
            seed_q = np.where(moving, seed_q, start)
            result = solve_pose(
                robot, targets, seed_q, limits=limits, restarts=restarts, seed=k, max_iterations=iterations
            )
            if not result.success:
                position, orientation = result.position_error.values(), result.orientation_error.values()
                closest = min(closest, (max(position, default=0.0), max(orientation, default=0.0)))
                continue
            d, pair = world.min_distance(result.q)
            if d < floor:
                reason = f"IK solutions collide ({pair[0]} / {pair[1]}: {d * 1e3:.1f} mm, {floor * 1e3:.1f} mm needed)"
                continue
            distance = float(np.linalg.norm(result.q - start))
            if d < margin:
                near.append((distance, result.q))
                continue
            if distance < clear_cost:
                clear_best, clear_cost = result.q, distance
            if k == 0:
                break  # warm start: the start seed's clear solution
        if clear_best is None:
            approached = _approached(world, sorted(near, key=lambda c: c[0]), start, limits, margin, floor)
            if approached is None and near:
                reason = f"no certified segment approaches the {len(near)} IK solutions inside the margin"
            near.clear()
        if clear_best is not None or approached is not None or time.perf_counter() >= deadline:
            break
    best = clear_best if clear_best is not None else approached
    if best is None:
        if reason.startswith("no IK solution") and np.isfinite(closest[0]):
            reason += f"; the closest ends {closest[0] * 1e3:.1f} mm / {closest[1]:.3f} rad from the target"
        inside = _targets_inside_obstacles(world, targets)
        if inside:
            raise PlanningError(f"goal {sorted(targets)}: {inside} ({reason})")
        if np.isfinite(closest[0]) and closest[0] > 0.05:
            raise PlanningError(f"goal {sorted(targets)}: out of reach ({reason})")
        raise PlanningError(f"goal {sorted(targets)}: unreachable without collision ({reason})")
    return best


def _approached(
    world: CollisionWorld,
    near: list[tuple[float, np.ndarray]],
    start: np.ndarray,
    limits: JointLimits,
    margin: float,
    floor: float,
) -> np.ndarray | None:
    """The first of ``near`` (solutions inside the margin, closest to the start first) that a certified segment of
    the joints it moves approaches (the segment plan_motion will follow), or None."""
    for _, q in near:
        active = np.flatnonzero(np.abs(q - start) > 1e-12)
        if approach_segment(world, q, "goal", active, limits.lower, limits.upper, margin, floor) is not None:
            return q
    return None


def _targets_inside_obstacles(world: CollisionWorld, targets: Mapping[str, Any]) -> str:
    """``"the target of right_ee is inside box"`` for every target position inside an obstacle, else ``""``."""
    import coal

    point = coal.Sphere(1e-4)
    found = []
    for frame, target in targets.items():
        try:
            position = as_pose(target)[:3, 3] if np.shape(target) != (3,) else np.asarray(target, dtype=float)
        except TaplanError:
            continue
        for obstacle in world.scene.obstacles.values():
            if hasattr(obstacle.shape, "contains"):  # voxels: a grid lookup (a coal octree took 20-50 ms to build)
                local = np.linalg.solve(obstacle.pose, np.append(position, 1.0))[:3]
                if obstacle.shape.contains(local[None, :])[0]:
                    found.append(f"the target of {frame} is inside {obstacle.name}")
                continue
            if not hasattr(obstacle.shape, "to_coal"):
                continue
            request, result = coal.DistanceRequest(), coal.DistanceResult()
            request.enable_signed_distance = True
            T = obstacle.pose
            d = coal.distance(
                obstacle.shape.to_coal(),
                coal.Transform3s(T[:3, :3], T[:3, 3]),
                point,
                coal.Transform3s(np.eye(3), position),
                request,
                result,
            )
            if d < 0:
                found.append(f"the target of {frame} is inside {obstacle.name}")
    return "; ".join(found)


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


def _concatenate(pieces: list[Trajectory]) -> Trajectory:
    """Rest-to-rest pieces (same joints) one after the other."""
    if len(pieces) == 1:
        return pieces[0]
    order = max(p.coefficients.shape[1] for p in pieces)
    times, coefficients, offset = [0.0], [], 0.0
    for p in pieces:
        c = p.coefficients
        coefficients.append(np.concatenate([c, np.zeros((c.shape[0], order - c.shape[1], c.shape[2]))], axis=1))
        times += list(offset + p.times[1:] - p.times[0])
        offset = times[-1]
    return Trajectory.from_polynomials(np.array(times), np.concatenate(coefficients), pieces[0].joint_names)


@dataclass(frozen=True)
class _Timed:
    trajectory: Trajectory
    min_clearance: float
    pair: tuple[str, str]
    attempts: int
    fallback: str = ""  # why and how a slower timing than the first was used ("" when the first verified)


@dataclass(frozen=True)
class _Timing:
    """One way to time the path: ruckig on a straight segment (``step`` None), else the jerk-limited filter of the
    path densified to ``step`` [rad] with corners cut by at most ``deviation`` [rad] (0: exact waypoints), under the
    limits scaled by ``speed``."""

    step: float | None
    deviation: float
    speed: float

    def describe(self) -> str:
        if self.step is None:
            what = "the straight segment"
        elif self.deviation > 0:
            what = f"corners cut by <= {self.deviation * 1e3:.0f} mrad"
        else:
            what = "the exact waypoints"
        return what + ("" if self.speed == 1.0 else f" at {self.speed:g} x the limits")


def _timings(two_points: bool, max_deviation: float) -> list[_Timing]:
    """The timings tried, the fastest expected first. A timing that cuts a corner into an obstacle is retried slower
    (a moving average cuts a corner in proportion to the speed) before tighter (the filter's corner repair slows
    the corners compoundingly and can crawl: 20 s instead of 0.8 s at the hardware limits)."""
    out = [_Timing(None, 0.0, 1.0)] if two_points else []
    out += [
        _Timing(DENSIFY_STEP, max_deviation, 1.0),
        _Timing(DENSIFY_STEP, max_deviation, 0.5),
        _Timing(DENSIFY_STEP / 2, max_deviation / 5, 1.0),  # jerk_limited: exact waypoints when that is faster
        _Timing(DENSIFY_STEP, max_deviation, 0.25),
        _Timing(DENSIFY_STEP / 4, 0.0, 1.0),  # the last resort, timed only when every other one failed
    ]
    return out


def _time_and_verify(
    robot: Robot,
    world: CollisionWorld,
    path: list[np.ndarray],
    approaches: list[Approach],
    active: np.ndarray,
    limits: JointLimits,
    q0: np.ndarray,
    q1: np.ndarray,
    margin: float,
    max_deviation: float,
    deadline: float,
    times: dict[str, float],
    certificate: SegmentCheck | None = None,
    fallbacks: bool = True,
) -> _Timed | str:
    """The timed, verified trajectory of ``path`` with its approach segments, or why there is none (a sentence).
    A straight path's ``certificate`` (``margin / 2`` along the segment) certifies its ruckig timing when that stays
    on the segment (:func:`_on_certified_segment`): no second certificate of the same configurations. Without
    ``fallbacks`` only the first timing is tried (a smoothed path, when a certified plan is in hand: the slower
    timings of the fallback chain can take seconds under load, past the budget)."""
    from taplan.timing.jerk_limited import jerk_limited
    from taplan.timing.straight import straight_line

    sub = limits.subset([robot.joint_names[i] for i in active])
    names = robot.joint_names
    lowest, lowest_pair = np.inf, ("", "")
    ends: dict[str, Trajectory] = {}
    for approach in approaches:  # straight rest-to-rest pieces exactly on their certified segments
        clock = time.perf_counter()
        a, b = (q0, approach.clear) if approach.end == "start" else (approach.clear, q1)
        piece = _full_trajectory(straight_line(a[active], b[active], sub), names, active, q0)
        times["timing"] += time.perf_counter() - clock
        clock = time.perf_counter()
        check = verify_trajectory(world, piece, floor=approach.certified - MIN_CERTIFIED, hold=q0, deadline=deadline)
        times["verify"] += time.perf_counter() - clock
        if not check.collision_free:
            return "the time budget ran out" if check.timed_out else f"the {approach.end} approach did not verify"
        ends[approach.end] = piece
        if check.min_clearance < lowest:
            lowest, lowest_pair = check.min_clearance, check.pair

    # A straight segment gets ruckig's time-optimal jerk-limited motion on it; polylines the filtered TOPP-RA. The
    # first timing is the fastest: when it verifies it is the plan. Otherwise the other timings are verified shortest
    # first, so a slower fallback is the fastest that is safe; a timing is computed only when it could be shorter than
    # the shortest one computed (its floor, :func:`_duration_floor`, is not longer): the same order as computing all.
    def timed(how: _Timing) -> Trajectory:
        scaled = sub.replace(
            velocity=sub.velocity * how.speed, acceleration=sub.acceleration * how.speed, jerk=sub.jerk * how.speed
        )
        if how.step is None:
            part = straight_line(path[0][active], path[1][active], scaled)
        else:
            part = jerk_limited(  # deviation 0: the "path" method, through every waypoint
                _densify(path, how.step)[:, active],
                scaled,
                method="joint" if how.deviation > 0 else "path",
                max_deviation=how.deviation,
                points_per_segment=TIMING_POINTS,
                min_grid_segments=TIMING_MIN_GRID,
            ).trajectory
        return _full_trajectory(part, names, active, q0)

    candidates: list[tuple[float, int, _Timing, Trajectory]] = []
    why = "no timing was tried"
    first: tuple[float, str] | None = None  # the fastest timing's duration and why it was not used
    verified = 0
    options = _timings(len(path) == 2, max_deviation)
    took = 0.0  # [s] the longest timing so far: another one starts only if that much of the budget is left

    def attempt(how: _Timing) -> Trajectory | None:
        """``timed(how)``, its time counted; None (and why) when the timing fails."""
        nonlocal why, took
        clock = time.perf_counter()
        try:
            return timed(how)
        except TimingError as exc:
            why = f"timing the path failed: {exc}"
            return None
        finally:
            took = max(took, time.perf_counter() - clock)
            times["timing"] += time.perf_counter() - clock

    how = options[0]  # the fastest expected
    middle = attempt(how)
    if middle is not None:
        verified += 1
        clock = time.perf_counter()
        if how.step is None and certificate is not None and _on_certified_segment(world, middle, path, margin):
            check = Verification(True, certificate.clearance, certificate.pair, 0.0, 0)
        else:
            check = verify_trajectory(world, middle, floor=margin / 4, hold=q0, deadline=deadline)
        times["verify"] += time.perf_counter() - clock
        if check.timed_out:
            return "the time budget ran out while verifying timing 1"
        if check.collision_free:
            return _finish(ends, middle, check, lowest, lowest_pair, 1, "")
        why = _too_close(check, margin / 4)
        first = (middle.duration, why)
    if not fallbacks:
        return why
    last = len(options) - 1

    def last_resort() -> list[tuple[float, int, _Timing, Trajectory]]:
        if time.perf_counter() + took >= deadline:
            return []
        middle = attempt(options[last])
        return [] if middle is None else [(middle.duration, last, options[last], middle)]

    floor_of = {rank: _duration_floor(path, active, sub, how) for rank, how in enumerate(options[:last]) if rank}
    pending = sorted(floor_of, key=lambda rank: (floor_of[rank], rank))  # fallbacks not computed yet

    def shortest() -> list[tuple[float, int, _Timing, Trajectory]]:
        """The shortest fallback by (duration, rank), computing those whose floor does not rule them out."""
        while pending and (not candidates or floor_of[pending[0]] <= candidates[0][0]):
            if time.perf_counter() + took >= deadline:
                pending.clear()
                break
            rank = pending.pop(0)
            middle = attempt(options[rank])
            if middle is not None:
                candidates.append((middle.duration, rank, options[rank], middle))
                candidates.sort(key=lambda c: (c[0], c[1]))
        return [candidates.pop(0)] if candidates else []

    queue = shortest() or last_resort()
    while queue:
        duration, rank, how, middle = queue.pop(0)
        if time.perf_counter() >= deadline:
            return f"the time budget ran out after {verified} verified timings ({why})"
        verified += 1
        clock = time.perf_counter()
        check = verify_trajectory(world, middle, floor=margin / 4, hold=q0, deadline=deadline)
        times["verify"] += time.perf_counter() - clock
        if check.timed_out:
            return f"the time budget ran out while verifying timing {verified}"
        if check.collision_free:
            fallback = f"timing fell back to {how.describe()}: {duration:.3f} s"
            if first is not None:
                fallback += f" (the fastest timing, {first[0]:.3f} s, {first[1]})"
            return _finish(ends, middle, check, lowest, lowest_pair, verified, fallback)
        why = _too_close(check, margin / 4)
        if rank < last:
            queue = shortest() or last_resort()
    return f"{why} after {verified} verified timings: not returned"


def _duration_floor(path: list[np.ndarray], active: np.ndarray, limits: JointLimits, how: _Timing) -> float:
    """A lower bound [s] of the duration of any timing of ``path`` under ``limits`` scaled by ``how.speed``: a timing
    goes from rest at the first waypoint to rest at the last (zero velocity and acceleration, as every plan) within
    the velocity, acceleration and jerk limits, so each joint takes at least the time-optimal rest-to-rest motion of
    its displacement (:func:`rest_to_rest_time`)."""
    from taplan.timing.straight import rest_to_rest_time

    travel = np.abs(path[-1][active] - path[0][active])
    s = how.speed
    times = rest_to_rest_time(travel, limits.velocity * s, limits.acceleration * s, limits.jerk * s)
    return float(np.max(times, initial=0.0)) * (1.0 - 1e-9)


def _too_close(check: Any, floor: float) -> str:
    """Why a timed trajectory was not certified, in words."""
    d, (a, b), t = check.min_clearance, check.pair, check.time
    where = f"({a} / {b} at t = {t:.3f} s)"
    if d < 0:
        return f"the timed trajectory goes {-d * 1e3:.1f} mm into collision {where}"
    return f"the timed trajectory comes within {d * 1e3:.1f} mm of collision {where}, {floor * 1e3:.1f} mm required"


def _finish(
    ends: dict[str, Trajectory],
    middle: Trajectory,
    check: Any,
    lowest: float,
    lowest_pair: tuple[str, str],
    attempts: int,
    fallback: str,
) -> _Timed:
    pieces = [p for p in (ends.get("start"), middle, ends.get("goal")) if p is not None]
    if check.min_clearance < lowest:
        lowest, lowest_pair = check.min_clearance, check.pair
    return _Timed(_concatenate(pieces), float(lowest), lowest_pair, attempts, fallback)


def _on_certified_segment(world: CollisionWorld, trajectory: Trajectory, path: list[np.ndarray], margin: float) -> bool:
    """True when ``trajectory`` (all joints) stays so close to the segment ``path[0] → path[1]`` (certified to keep
    ``margin / 2``) that it keeps more than ``margin / 4``: per joint its deviation from the segment is bounded by the
    part of each coefficient across the segment's direction (``Σ_k |r_k| h^k`` per piece) plus any overshoot of the
    segment parameter beyond [0, 1] (exact range of that polynomial); the robot's points then move at most
    ``Σ_j reach_j dev_j`` [m] off the certified configurations."""
    from taplan.timing._polynomial import position_range

    a, b = path[0], path[1]
    d = b - a
    norm2 = float(d @ d)
    if norm2 <= 0.0:
        return False
    c = trajectory.coefficients.copy()  # (m, order, nq)
    c[:, 0] -= a
    along = np.einsum("mkj,j->mk", c, d) / norm2  # the segment parameter's coefficients
    across = c - along[:, :, None] * d  # what leaves the segment
    h = np.diff(trajectory.times)
    powers = h[:, None] ** np.arange(c.shape[1])[None, :]  # (m, order)
    deviation = (np.abs(across) * powers[:, :, None]).sum(axis=1).max(axis=0)  # per joint, worst piece [rad]
    s = Trajectory.from_polynomials(trajectory.times, along[:, :, None], ("s",))
    low, high = position_range(s)
    overshoot = max(0.0, float(high[0]) - 1.0, -float(low[0]))
    deviation = deviation + overshoot * np.abs(d)
    off = world.max_point_speed_bound(np.zeros_like(a), deviation)
    return margin / 2 - off > margin / 4 + MIN_CERTIFIED


def _check_budget(max_time: Any) -> float:
    if not (isinstance(max_time, (int, float)) and np.isfinite(max_time) and max_time > 0):
        raise InvalidInputError("max_time", max_time, "a time budget > 0 [s]")
    return float(max_time)


def _end_clearance(world: CollisionWorld, q: np.ndarray, argument: str, floor: float) -> tuple[float, tuple[str, str]]:
    """The smallest distance [m] of an end and its pair (one query serves the floor check and the approach)."""
    d, pair = world.min_distance(q)
    if d < floor:
        raise CollisionError(argument, pair, -d, floor)
    return d, pair


@run_single_threaded  # small arrays: BLAS/OpenMP worker threads cost more than they save (taplan._threads)
def plan_motion(
    robot: Robot,
    start: npt.ArrayLike,
    goal: npt.ArrayLike | Mapping[str, Any],
    scene: Scene | None = None,
    limits: JointLimits | None = None,
    *,
    world: CollisionWorld | None = None,
    margin: float = DEFAULT_MARGIN,
    floor: float = DEFAULT_FLOOR,
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
        floor: Hard floor [m] (``0 < floor <= margin``): a start or goal closer than ``margin`` but at least
            ``floor`` from everything is left or approached along a short certified segment whose clearance only
            shrinks toward it (``report.approaches``); only one inside the floor is refused.
        max_deviation: Largest corner cut of the jerk-limited timing at interior waypoints [rad] (the first timing;
            when its verification fails the retries cut a fifth of it, then follow the waypoints exactly).
        max_time: Time budget of the whole call (goal IK, path, smoothing, timing, verification) [s]; the call
            returns or raises within ``max_time + BUDGET_TOLERANCE`` (one indivisible step: an IK solve, a QP, a
            timing). A sampled path whose smoothing does not fit is returned unsmoothed (``report.notes`` says so).
            The first call of a process loads the compiled kernels before the budget starts (~0.2 s; once after
            installing, a few seconds of compilation: :mod:`~taplan.planning.kernels_ready`).
        stages: Path stages to try, in this order: any of ``"straight"``, ``"optimization"``, ``"rrt-connect"``.
        ik_seeds: Random seeds of the goal IK beyond the start and home.
        seed: Seed of every random choice (reproducible plans).

    Returns:
        The verified plan.

    Raises:
        InvalidInputError: malformed start, goal or option (shape, NaN, outside the limits).
        CollisionError: start or goal inside the floor (names the pair and the distance in mm).
        PlanningError: unreachable goal pose, no path or no verified timing within ``max_time``.
    """
    load_compiled_kernels(robot)  # their first call in a process: outside the budget (taplan.planning.kernels_ready)
    begin = time.perf_counter()
    times = dict.fromkeys(("validate", "goal_ik", "straight", "optimize", "sample", "smooth", "timing", "verify"), 0.0)
    limits = robot.planning_limits if limits is None else limits
    if not isinstance(limits, JointLimits) or limits.names != robot.joint_names:
        raise InvalidInputError("limits", limits, f"JointLimits over the robot's joints {robot.joint_names}")
    if not (isinstance(margin, (int, float)) and np.isfinite(margin) and margin > 0):
        raise InvalidInputError("margin", margin, "a clearance > 0 [m]")
    if not (isinstance(floor, (int, float)) and np.isfinite(floor) and 0 < floor <= margin):
        raise InvalidInputError("floor", floor, f"a hard floor in (0, margin = {margin:g}] [m]")
    if not (isinstance(stages, tuple) and stages and set(stages) <= set(STAGES)):
        raise InvalidInputError("stages", stages, f"a non-empty tuple of {STAGES}")
    deadline = begin + _check_budget(max_time)
    world = world if world is not None else CollisionWorld(robot, scene)
    q0 = robot.check_configuration(start, "start")
    if not limits.within(q0):
        raise InvalidInputError("start", np.round(q0, 4).tolist(), "a configuration within the limits")
    clearance = {"start": _end_clearance(world, q0, "start", floor)}
    rng = np.random.default_rng(seed)
    times["validate"] = time.perf_counter() - begin

    clock = time.perf_counter()
    if isinstance(goal, Mapping):
        ik_deadline = begin + IK_SHARE * max_time
        q1 = _goal_ik(robot, world, goal, q0, limits, margin, floor, ik_seeds, rng, ik_deadline)
    else:
        q1 = robot.check_configuration(goal, "goal")
        if not limits.within(q1):
            raise InvalidInputError("goal", np.round(q1, 4).tolist(), "a configuration within the limits")
        clearance["goal"] = _end_clearance(world, q1, "goal", floor)
    times["goal_ik"] = time.perf_counter() - clock

    active = np.flatnonzero(np.abs(q1 - q0) > 1e-12)
    if active.size == 0:
        raise InvalidInputError("goal", "the start configuration", "a goal that differs from the start")
    clock = time.perf_counter()
    approaches: list[Approach] = []
    for end, q_end in (("start", q0), ("goal", q1)):
        d, pair = clearance[end] if end in clearance else world.min_distance(q_end)
        if d >= margin:
            continue
        approach = approach_segment(world, q_end, end, active, limits.lower, limits.upper, margin, floor)
        if approach is None:
            raise PlanningError(
                f"{end}: {pair[0]} is {d * 1e3:.1f} mm from {pair[1]} (margin {margin * 1e3:.1f} mm, floor "
                f"{floor * 1e3:.1f} mm) and no short certified segment of the joints that move leads away from it"
            )
        approaches.append(approach)
    times["validate"] += time.perf_counter() - clock
    a = next((p.clear for p in approaches if p.end == "start"), q0)
    b = next((p.clear for p in approaches if p.end == "goal"), q1)
    reserve = float(np.clip(FINISH_SHARE * max_time, FINISH_MIN, FINISH_MAX))
    if np.abs(b - a).max() > 1e-12:
        found = _find_path(
            world, a, b, active, limits, margin, floor, stages, deadline - reserve, rng, times, certify=False
        )
        if found is None:
            raise PlanningError(
                f"no collision-free path found within {max_time:g} s (stages: {', '.join(stages)}; "
                f"{reserve:.2f} s of the budget kept for timing and verification)"
            )
        stage, path, certificate, kept = found
    else:
        stage, path, certificate, kept = "straight", [a, b], None, margin  # both ends retreat to one clear one
    notes: list[str] = []
    timed: _Timed | str | None = None
    smoothed = False
    if stage == "rrt-connect":
        # the sampled path is smoothed first (tens of ms) and only its fastest timing tried: the certified unsmoothed
        # path, with the whole fallback chain, is the plan when that fails
        left = deadline - time.perf_counter()
        if left < SMOOTH_MIN:
            notes.append(
                f"smoothing skipped: {max(left, 0.0):.2f} s of the {max_time:g} s budget left; the certified "
                "unsmoothed path is returned"
            )
        else:
            clock = time.perf_counter()
            smooth = _smooth_sampled(world, path, active, kept, rng, clock + SMOOTH_SHARE * left)
            times["smooth"] += time.perf_counter() - clock
            if smooth is None:
                notes.append("the smoothed path was not certified in time; the certified unsmoothed path is returned")
            else:  # half the time left: the other half times and verifies the unsmoothed path if this fails
                better = _time_and_verify(
                    robot,
                    world,
                    smooth,
                    approaches,
                    active,
                    limits,
                    q0,
                    q1,
                    kept,
                    max_deviation,
                    (time.perf_counter() + deadline) / 2,
                    times,
                    fallbacks=False,
                )
                if isinstance(better, str):
                    notes.append(
                        f"the smoothed path was not used ({better}); the certified unsmoothed path is returned"
                    )
                else:
                    path, timed, smoothed = smooth, better, True
    if timed is None and stage == "rrt-connect":
        # the sampled path itself was not certified yet (its smoothed path carried the certificate): now it is, and
        # if an edge is refused the sampler searches again, certifying what it finds
        clock = time.perf_counter()
        certified = certify_path(world, path, kept, deadline)
        times["sample"] += time.perf_counter() - clock
        if certified is None and time.perf_counter() < deadline:
            again = _find_path(
                world,
                a,
                b,
                active,
                limits,
                margin,
                floor,
                ("rrt-connect",),
                (time.perf_counter() + deadline) / 2,
                rng,
                times,
                certify=True,
            )
            if again is not None:
                certified, kept = again[1], again[3]
        if certified is None:
            raise PlanningError(f"no sampled path was certified within {max_time:g} s")
        path = certified
    if timed is None:
        timed = _time_and_verify(
            robot, world, path, approaches, active, limits, q0, q1, kept, max_deviation, deadline, times, certificate
        )
        if isinstance(timed, str):
            raise PlanningError(timed)
    if kept < margin:
        notes.insert(
            0,
            f"no path that keeps the {margin * 1e3:.1f} mm margin was found in time; this one keeps "
            f"{kept * 1e3:.2f} mm (edges half, the timed trajectory a quarter)",
        )
    geometric = np.array(path)
    report = PlanReport(
        success=True,
        stage=stage,
        stage_times=times,
        path_length=_length(geometric) + sum(p.length for p in approaches),
        duration=timed.trajectory.duration,
        min_clearance=timed.min_clearance,
        min_clearance_pair=timed.pair,
        waypoints=len(path),
        timing_attempts=timed.attempts,
        smoothed=smoothed,
        margin=kept,
        goal=q1,
        approaches=tuple(approaches),
        notes=tuple(notes) + ((timed.fallback,) if timed.fallback else ()),
        timing_fallback=timed.fallback,
        elapsed=time.perf_counter() - begin,
    )
    full_path = (
        [q0] * ("start" in {p.end for p in approaches})
        + list(geometric)
        + [q1] * ("goal" in {p.end for p in approaches})
    )
    return MotionPlan(timed.trajectory, np.array(full_path), report)
