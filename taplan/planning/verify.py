"""Collision verification with a guarantee: conservative advancement along joint-space segments and timed
trajectories.

The distance of each pair (robot body, obstacle or other body) changes by at most ``travel_p · |Δq|`` between two
configurations (``travel_p``: the reach of every joint that moves either member, :class:`~taplan.scene.Distances`),
so a step that keeps ``travel_p · |Δq| < d_p − floor`` for every pair keeps at least ``floor`` of clearance all along
it. Stepping like that certifies a whole segment or trajectory, not only its samples (conservative advancement).
Along a timed trajectory ``|Δq_j|`` over ``Δt`` is bounded by ``Δt · max|q̇_j|`` with the exact peak speeds of the
polynomial pieces in the window, and the distances at both ends of an interval bound it from both sides (the
interval is halved until the bound holds).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from taplan.scene.world import CollisionWorld
from taplan.timing._polynomial import max_abs_derivative
from taplan.trajectory import Trajectory

__all__ = ["SegmentCheck", "check_segment", "verify_trajectory", "Verification"]

MIN_CERTIFIED = 1e-4  # [m] below this clearance a step would be too small to certify: report a failure
LOOKAHEAD = 0.1  # [s] window over which the peak joint speeds bound a trajectory step
MIN_FRACTION = 1e-9  # a segment interval this short that still cannot be certified is a failure
MIN_INTERVAL = 1e-6  # [s] a trajectory interval this short that still cannot be certified is a failure
BOUND_BEYOND = 0.1  # [m] pairs whose bounding spheres are farther apart use that gap (a lower bound): no coal query


@dataclass(frozen=True)
class SegmentCheck:
    """Outcome of a segment check: ``valid``, the smallest clearance seen [m] and where (fraction in [0, 1])."""

    valid: bool
    clearance: float
    pair: tuple[str, str]
    evaluations: int


def check_segment(
    world: CollisionWorld, q_a: np.ndarray, q_b: np.ndarray, margin: float, *, points: float | None = None
) -> SegmentCheck:
    """Certify that the straight joint-space segment keeps at least ``margin / 2`` [m] everywhere and ``points``
    (default ``margin``) at the evaluated configurations; invalid as soon as one is closer than ``points``.

    Per pair, the distance changes by at most ``travel_p · |Δq|`` over the segment, so on ``[s_a, s_b]`` it stays
    above ``(d_a + d_b − rate_p (s_b − s_a)) / 2`` with ``rate_p = travel_p · |q_b − q_a|``: intervals are halved
    until that bound is at least ``margin / 2`` for every pair.
    """
    step = np.abs(q_b - q_a)
    lowest, lowest_pair = math.inf, ("", "")
    evaluations = 0
    floor = margin / 2
    required = margin if points is None else max(float(points), floor + MIN_CERTIFIED)

    def evaluate(s: float) -> tuple[np.ndarray, np.ndarray, bool]:
        nonlocal lowest, lowest_pair, evaluations
        distances = world.distances(q_a + s * (q_b - q_a), jacobian=False, bound_beyond=BOUND_BEYOND)
        d, pair = distances.closest()
        evaluations += 1
        if d < lowest:
            lowest, lowest_pair = d, pair
        assert distances.travel is not None
        return distances.distance, distances.travel @ step, d >= required

    d_a, rate, ok = evaluate(0.0)
    if not ok:
        return SegmentCheck(False, lowest, lowest_pair, evaluations)
    if not np.any(rate > 0):
        return SegmentCheck(True, lowest, lowest_pair, evaluations)
    d_b, _, ok = evaluate(1.0)
    if not ok:
        return SegmentCheck(False, lowest, lowest_pair, evaluations)
    valid = _halve_until_certified(
        (0.0, d_a, 1.0, d_b), evaluate, lambda a, b: rate, lambda lower: bool(np.all(lower >= floor)), MIN_FRACTION
    )
    return SegmentCheck(valid, lowest, lowest_pair, evaluations)


def _halve_until_certified(
    interval: tuple[float, np.ndarray, float, np.ndarray],
    evaluate: Callable[[float], tuple[np.ndarray, Any, bool]],
    rate: Callable[[float, float], np.ndarray],
    clears: Callable[[np.ndarray], bool],
    shortest: float,
) -> bool:
    """Certify ``interval`` ``(a, d_a, b, d_b)`` (per-pair distances at both ends): per pair the distance stays
    above ``(d_a + d_b − rate(a, b) (b − a)) / 2`` on it; where ``clears`` refuses that bound, halve (evaluating
    the middle) depth first, earliest part first. False when an evaluation fails or a part shorter than
    ``shortest`` still does not clear."""
    pending = [interval]
    while pending:
        a, da, b, db = pending.pop()
        if clears((da + db - rate(a, b) * (b - a)) / 2):
            continue
        if b - a < shortest:
            return False
        m = (a + b) / 2
        dm, _, ok = evaluate(m)
        if not ok:
            return False
        pending += [(m, dm, b, db), (a, da, m, dm)]
    return True


@dataclass(frozen=True)
class Verification:
    """Outcome of :func:`verify_trajectory`.

    Attributes:
        collision_free: True when the whole trajectory is certified to keep at least ``floor`` [m].
        min_clearance: Smallest clearance at the evaluated times [m].
        pair: Where it occurs.
        time: When it occurs [s].
        evaluations: Distance evaluations used.
        timed_out: True when the ``deadline`` passed before the certificate was complete (not collision-free then).
    """

    collision_free: bool
    min_clearance: float
    pair: tuple[str, str]
    time: float
    evaluations: int
    timed_out: bool = False


def verify_trajectory(
    world: CollisionWorld,
    trajectory: Trajectory,
    floor: float = 0.0,
    hold: np.ndarray | None = None,
    *,
    deadline: float = math.inf,
) -> Verification:
    """Certify ``trajectory`` keeps more than ``floor`` [m] of clearance at every instant.

    Each pair's distance changes at most at ``rate_p = travel_p · max|q̇|`` (exact peak joint speeds of the pieces
    in the interval), so over ``[t_a, t_b]`` it stays above ``(d_a + d_b − rate_p (t_b − t_a)) / 2``. Windows of
    ``LOOKAHEAD`` are certified with that two-sided bound and halved until every pair passes; an evaluated
    clearance within ``MIN_CERTIFIED`` of ``floor`` is a failure.

    Args:
        world: The collision world.
        trajectory: Joints matched by name to the robot.
        floor: Clearance to certify [m].
        hold: Positions [rad] (nq,) of the robot's joints the trajectory does not drive; default ``robot.home``.
        deadline: ``time.perf_counter()`` value after which the certificate stops (checked per ``LOOKAHEAD``
            window): the result is then not collision-free and ``timed_out``.
    """
    names = trajectory.joint_names
    robot = world.robot
    index = robot.indices(names)
    speeds = np.zeros((len(trajectory.times) - 1, robot.nq))
    speeds[:, index] = max_abs_derivative(trajectory, 1)  # exact peak |q̇| per piece and joint [rad/s]
    times = trajectory.times
    base = robot.home.copy() if hold is None else np.asarray(hold, dtype=float).copy()
    lowest, pair, when = math.inf, ("", ""), float(times[0])
    evaluations = 0

    def evaluate(t: float) -> tuple[np.ndarray, np.ndarray, bool]:
        nonlocal lowest, pair, when, evaluations
        q = base.copy()
        q[index] = trajectory(t)
        distances = world.distances(q, jacobian=False, bound_beyond=BOUND_BEYOND)
        evaluations += 1
        d, p = distances.closest()
        if d < lowest:
            lowest, pair, when = d, p, t
        assert distances.travel is not None
        return distances.distance, distances.travel, d - floor >= MIN_CERTIFIED

    def peak(t_a: float, t_b: float) -> np.ndarray:
        lo = max(int(np.searchsorted(times, t_a, side="right")) - 1, 0)
        hi = int(np.searchsorted(times, t_b, side="left"))
        return speeds[lo : max(hi, lo + 1)].max(axis=0)

    start, end = float(times[0]), float(times[-1])
    grid = np.append(np.arange(start, end, LOOKAHEAD), end)
    d_a, travel, ok = evaluate(start)
    if not ok:
        return Verification(False, lowest, pair, when, evaluations)
    for t_a, t_b in zip(grid[:-1], grid[1:], strict=True):
        if time.perf_counter() > deadline:
            return Verification(False, lowest, pair, when, evaluations, timed_out=True)
        d_b, _, ok = evaluate(float(t_b))
        if not ok:
            return Verification(False, lowest, pair, when, evaluations)
        certified = _halve_until_certified(
            (float(t_a), d_a, float(t_b), d_b),
            evaluate,
            lambda a, b: travel @ peak(a, b),
            lambda lower: bool(np.all(lower > floor)),
            MIN_INTERVAL,
        )
        if not certified:
            return Verification(False, lowest, pair, when, evaluations)
        d_a = d_b
    return Verification(True, lowest, pair, when, evaluations)
