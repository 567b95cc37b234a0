"""Margins that bend at the ends: leaving a start, or approaching a goal, that is closer to something than the path
margin but clear of a hard floor.

The path keeps ``margin`` wherever it can. A start or goal whose clearance ``d`` lies in ``[floor, margin)`` (a grasp,
a placement) is joined to the rest of the plan by a short straight joint-space segment to a *clear* configuration
(at least ``margin`` from everything, found by moving the closest pairs apart with small QPs on their distance
Jacobians). That segment is certified by conservative advancement to keep ``floor + (d − floor) / 2`` everywhere,
and its clearance only shrinks toward the end: the closest distance at every evaluated configuration, ordered from
the clear configuration to the end, never grows by more than ``MONOTONE_SLACK``. Only configurations inside
``floor`` are refused (:class:`~taplan.errors.CollisionError` naming the pair and the distance).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import qpsolvers

from taplan.planning.verify import BOUND_BEYOND, MIN_FRACTION, _halve_until_certified
from taplan.scene.world import CollisionWorld

__all__ = ["Approach", "DEFAULT_FLOOR", "approach_segment"]

DEFAULT_FLOOR = 0.0025  # [m] the hard floor: starts and goals closer than this to anything are refused
RETREAT_TARGET = 1.5  # the clear configuration aims at this multiple of the margin (room for the path's margin)
RETREAT_STEP = 0.05  # [rad] largest joint step (max-norm) of one retreat iteration
RETREAT_ITERATIONS = 30
MAX_TRAVEL = 0.08  # [m] an approach segment moves no point of the robot farther than this ("short")
MONOTONE_SLACK = 1e-4  # [m] numerical slack of "the clearance only shrinks toward the end"


@dataclass(frozen=True)
class Approach:
    """A bent end of a plan.

    Attributes:
        end: ``"start"`` (the plan leaves it) or ``"goal"`` (the plan approaches it).
        clearance: Clearance of the end configuration [m] (below the margin, at least the floor).
        pair: The closest pair at the end.
        certified: The approach segment is certified to keep at least this clearance [m] everywhere.
        length: Joint-space length of the segment [rad].
        travel: Upper bound on how far any robot point moves along it [m].
        clear: The configuration at the other end of the segment [rad] (nq,): at least ``margin`` from everything.
    """

    end: str
    clearance: float
    pair: tuple[str, str]
    certified: float
    length: float
    travel: float
    clear: np.ndarray = field(repr=False)


def _retreat(
    world: CollisionWorld, q_end: np.ndarray, active: np.ndarray, lower: np.ndarray, upper: np.ndarray, margin: float
) -> np.ndarray | None:
    """A configuration near ``q_end`` (moving only ``active``) with clearance >= ``margin``, or None."""
    target = RETREAT_TARGET * margin
    q = q_end.copy()
    for _ in range(RETREAT_ITERATIONS):
        d = world.distances(q, cutoff=target + 0.02)
        if d.closest()[0] >= target:
            break
        assert d.jacobian is not None
        J = d.jacobian[:, active]
        keep = np.any(J != 0.0, axis=1)
        if not keep.any():
            return None  # the close pairs do not move with these joints
        n = active.size
        lb = np.maximum(-RETREAT_STEP, lower[active] - q[active])
        ub = np.minimum(RETREAT_STEP, upper[active] - q[active])
        # the least joint motion that pushes every close pair to the target (linearised), within the step
        step = qpsolvers.solve_qp(
            np.eye(n), np.zeros(n), -J[keep], d.distance[keep] - target, lb=lb, ub=ub, solver="daqp"
        )
        if step is None:  # the target is out of reach in one step: go as far as the step allows toward it
            gradient = J[keep][int(np.argmin(d.distance[keep]))]
            norm = float(np.abs(gradient).max())
            if norm <= 0.0:
                return None
            step = np.clip(gradient / norm * RETREAT_STEP, lb, ub)
        q = q.copy()
        q[active] += step
        if world.max_point_speed_bound(q_end, q) > MAX_TRAVEL:
            return None
    return q if world.min_distance(q)[0] >= margin else None


def approach_segment(
    world: CollisionWorld,
    q_end: np.ndarray,
    end: str,
    active: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    margin: float,
    floor: float,
) -> Approach | None:
    """The certified segment between ``q_end`` (clearance in ``[floor, margin)``) and a clear configuration; None
    when no retreat within ``MAX_TRAVEL`` keeps the clearance shrinking monotonically toward ``q_end``."""
    clearance, pair = world.min_distance(q_end)
    certified = floor + (clearance - floor) / 2
    clear = _retreat(world, q_end, active, lower, upper, margin)
    while clear is not None:
        if _certify(world, clear, q_end, certified):
            return Approach(
                end,
                clearance,
                pair,
                certified,
                float(np.linalg.norm(clear - q_end)),
                world.max_point_speed_bound(clear, q_end),
                clear,
            )
        # curvature bent the segment: a shorter one, if it is still clear
        shorter = q_end + (clear - q_end) * 0.6
        clear = shorter if world.min_distance(shorter)[0] >= margin else None
    return None


def _certify(world: CollisionWorld, q_clear: np.ndarray, q_end: np.ndarray, floor: float) -> bool:
    """The segment from ``q_clear`` (s = 0) to ``q_end`` (s = 1) keeps more than ``floor`` everywhere (conservative
    advancement) and its closest distance at the evaluated points does not grow toward ``q_end``."""
    step = np.abs(q_end - q_clear)
    seen: list[tuple[float, float]] = []

    def evaluate(s: float) -> tuple[np.ndarray, np.ndarray, bool]:
        distances = world.distances(q_clear + s * (q_end - q_clear), jacobian=False, bound_beyond=BOUND_BEYOND)
        d = distances.closest()[0]
        seen.append((s, d))
        assert distances.travel is not None
        return distances.distance, distances.travel @ step, d > floor

    grid = np.linspace(0.0, 1.0, 6)  # evenly spaced points: the monotonicity is seen along the whole segment
    ends = []
    rate = np.zeros(0)
    for s in grid:
        d, rate, ok = evaluate(float(s))
        if not ok:
            return False
        ends.append(d)
    travel = rate  # per pair [m] over the whole segment (the same pairs at every configuration)
    for k in range(len(grid) - 1):
        if not _halve_until_certified(
            (float(grid[k]), ends[k], float(grid[k + 1]), ends[k + 1]),
            evaluate,
            lambda a, b: travel,
            lambda lower: bool(np.all(lower > floor)),
            MIN_FRACTION,
        ):
            return False
    seen.sort()
    lowest_so_far = math.inf
    for _, d in seen:
        if d > lowest_so_far + MONOTONE_SLACK:
            return False
        lowest_so_far = min(lowest_so_far, d)
    return True
