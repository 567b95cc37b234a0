"""Collision verification with a guarantee: conservative advancement along joint-space segments and timed
trajectories.

The distance of each pair (robot body, obstacle or other body) changes by at most ``travel_p · |Δq|`` between two
configurations (``travel_p``: the reach of every joint that moves either member, :class:`~taplan.scene.Distances`),
so a step that keeps ``travel_p · |Δq| < d_p − floor`` for every pair keeps at least ``floor`` of clearance all along
it. Stepping like that certifies a whole segment or trajectory, not only its samples (conservative advancement).
Along a timed trajectory ``|Δq_j|`` over ``Δt`` is bounded by ``Δt · max|q̇_j|`` with bounds of the speeds of the
polynomial pieces in the window (their Bernstein coefficients), and the distances at both ends of an interval bound
it from both sides (the interval is split until the bound holds).

Both certificates work on whole batches (:func:`_certify_batch`): every configuration a level of halving needs, for
every segment or window at once, is one call of the world's batched distances (:mod:`taplan.scene.engine`), so a
certificate costs a handful of batched evaluations instead of one distance query per point.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from taplan.errors import InvalidInputError
from taplan.scene.world import CollisionWorld
from taplan.timing._polynomial import derivative_bound
from taplan.trajectory import Trajectory

__all__ = ["SegmentCheck", "check_segment", "check_segments", "check_path", "verify_trajectory", "Verification"]

MIN_CERTIFIED = 1e-4  # [m] below this clearance a step would be too small to certify: report a failure
LOOKAHEAD = 0.1  # [s] window over which the peak joint speeds bound a trajectory step
MIN_FRACTION = 1e-9  # a segment interval this short that still cannot be certified is a failure
MIN_INTERVAL = 1e-6  # [s] a trajectory interval this short that still cannot be certified is a failure
BOUND_BEYOND = 0.1  # [m] pairs whose bounding spheres are farther apart use that gap (a lower bound): no coal query
INITIAL_INTERVALS = 4  # a segment's first batch: its ends and this many intervals between them
# an uncertified interval is split into the pieces its worst pair needs by the mean of its ends' distances (this
# factor more, so that one level usually suffices), at least 2 (halving) and at most MAX_PIECES
SPLIT_SAFETY, MAX_PIECES = 1.25, 8


@dataclass(frozen=True)
class KnownDistances:
    """Distances already evaluated along S segments, for :func:`check_segments`: at the ``fractions`` (G,) of every
    segment (0 first, 1 last, increasing), ``distance`` (S, G, P) of every pair ``pairs`` (exact or lower bounds)
    with their ``travel`` rows (P, nv) (:class:`~taplan.scene.engine.BatchDistances`)."""

    fractions: np.ndarray
    pairs: tuple[tuple[str, str], ...]
    distance: np.ndarray
    travel: np.ndarray


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
    until that bound is at least ``margin / 2`` for every pair (:func:`check_segments` with one segment).
    """
    return check_segments(world, np.asarray(q_a)[None], np.asarray(q_b)[None], margin, points=points)[0]


def check_segments(
    world: CollisionWorld,
    starts: np.ndarray,
    ends: np.ndarray,
    margin: float,
    *,
    points: float | None = None,
    deadline: float = math.inf,
    known: KnownDistances | None = None,
) -> list[SegmentCheck]:
    """:func:`check_segment` for S segments ``starts[k] → ends[k]`` ((S, nq) each) in one batch: every level of
    halving evaluates the middles of all the intervals not yet certified, of every segment, in one call. A segment
    stops at its first evaluation closer than ``points``. Past ``deadline`` the unfinished segments are invalid.

    ``known``: distances of every pair already evaluated at the same fractions of every segment (the optimiser's
    waypoints and midpoints); they are the first level instead of the default grid, which costs no evaluation."""
    if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not (0 <= margin < math.inf):
        raise InvalidInputError("margin", margin, "a clearance >= 0 [m]")
    if points is not None and not (isinstance(points, (int, float)) and 0 <= points < math.inf):
        raise InvalidInputError("points", points, "a clearance >= 0 [m] or None")
    starts = np.atleast_2d(np.asarray(starts, dtype=float))
    ends = np.atleast_2d(np.asarray(ends, dtype=float))
    floor = margin / 2
    required = margin if points is None else max(float(points), floor + MIN_CERTIFIED)
    delta = ends - starts
    step = np.abs(delta)
    grid = np.linspace(0.0, 1.0, INITIAL_INTERVALS + 1)
    # a segment no robot point moves along needs its first point only
    moving = world.max_point_speed_bounds(step) > 0.0

    def configurations(segment: np.ndarray, s: np.ndarray) -> np.ndarray:
        return starts[segment] + s[:, None] * delta[segment]

    if known is not None:
        fractions = np.asarray(known.fractions, dtype=float)
        if (
            known.distance.shape[:2] != (len(starts), len(fractions))
            or fractions[0] != 0.0
            or fractions[-1] != 1.0
            or np.any(np.diff(fractions) <= 0.0)
        ):
            raise InvalidInputError(
                "known", f"distances {known.distance.shape} at fractions {fractions.tolist()}", "(S, G, P) at 0..1"
            )
        grid = fractions
    grids = [grid if moving[k] or known is not None else grid[:1] for k in range(len(starts))]
    curves = np.concatenate(grids)
    outcome = _certify_batch(
        world,
        len(starts),
        grids,
        configurations,
        lambda segment, a, b, travel: step[segment] @ travel.T,
        floor,
        required,
        MIN_FRACTION,
        deadline,
        strict=False,
        known=None if known is None else (known.pairs, known.distance.reshape(len(curves), -1), known.travel),
    )
    return [SegmentCheck(valid, low, pair, count) for valid, low, pair, _, count in outcome]


def check_path(
    world: CollisionWorld, path: np.ndarray, margin: float, *, points: float | None = None, deadline: float = math.inf
) -> SegmentCheck:
    """Certify the polyline ``path`` (K, nq) as :func:`check_segments` certifies its K − 1 edges (``margin / 2``
    everywhere, ``points`` at the evaluations), but as one curve: its first level is the K vertices, each evaluated
    once (every edge shares its ends with its neighbours; the segments' default grid evaluated 4 + 1 points per edge,
    the shared ones twice), and only the edges whose bound does not hold between their ends are split, into the
    pieces their closest pair needs. A smoothed sampled path has short edges (0.1 rad), most of them certified by
    their ends alone: 2-3x fewer evaluations than the segments' grid (issue 22's profile). The parameter ``s`` runs
    from 0 to K − 1, edge ``k`` over ``[k, k + 1]``; ``clearance`` and ``pair`` are the lowest evaluated ones."""
    if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not (0 <= margin < math.inf):
        raise InvalidInputError("margin", margin, "a clearance >= 0 [m]")
    if points is not None and not (isinstance(points, (int, float)) and 0 <= points < math.inf):
        raise InvalidInputError("points", points, "a clearance >= 0 [m] or None")
    P = np.asarray(path, dtype=float)
    if P.ndim != 2 or len(P) < 2 or P.shape[1] != world.model.nq:
        raise InvalidInputError("path", f"an array of shape {P.shape}", f"(K >= 2, {world.model.nq}) configurations")
    floor = margin / 2
    required = margin if points is None else max(float(points), floor + MIN_CERTIFIED)
    delta = np.diff(P, axis=0)
    step = np.abs(delta)
    last = len(delta) - 1

    def configurations(curve: np.ndarray, s: np.ndarray) -> np.ndarray:
        k = np.clip(np.floor(s).astype(int), 0, last)
        return P[k] + (s - k)[:, None] * delta[k]

    def rate(curve: np.ndarray, a: np.ndarray, b: np.ndarray, travel: np.ndarray) -> np.ndarray:
        """Per interval and pair, the travel rate per unit of ``s``: the edge's, or for an interval over several
        edges (the whole path, to find the joints that never move) the largest step of each joint among them."""
        first = np.clip(np.floor(a).astype(int), 0, last)
        final = np.clip(np.ceil(b).astype(int) - 1, first, last)
        steps = step[first].copy()
        for i in np.flatnonzero(final > first):
            steps[i] = step[first[i] : final[i] + 1].max(axis=0)
        return steps @ travel.T

    ((valid, low, pair, _, count),) = _certify_batch(
        world,
        1,
        [np.arange(len(P), dtype=float)],
        configurations,
        rate,
        floor,
        required,
        MIN_FRACTION,
        deadline,
        strict=False,
    )
    return SegmentCheck(valid, low, pair, count)


def _certify_batch(
    world: CollisionWorld,
    count: int,
    grids: list[np.ndarray],
    configurations: Callable[[np.ndarray, np.ndarray], np.ndarray],
    rate: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray],
    floor: float,
    required: float,
    shortest: float,
    deadline: float,
    *,
    strict: bool,
    known: tuple[tuple[tuple[str, str], ...], np.ndarray, np.ndarray] | None = None,
) -> list[tuple[bool, float, tuple[str, str], float, int]]:
    """Certify ``count`` curves (segments, trajectories) at once: per curve the intervals between consecutive
    parameters of its grid, halved level by level until every pair's two-sided bound
    ``(d_a + d_b − rate (b − a)) / 2`` is at least ``floor`` (> ``floor`` when ``strict``). ``configurations(curve,
    s)`` gives the configurations at parameters ``s`` of the curves ``curve`` (arrays), ``rate(curve, a, b,
    travel)`` each interval's per-pair rate (I, P) from the pairs' travel rows (P, nv). A curve fails at an
    evaluation closer than ``required``, an interval shorter than ``shortest`` that still does not clear, or the
    ``deadline``. ``known`` (pairs, distances (len of the grids together, P), travel rows (P, nv)): the distances
    at the grids, evaluated already (exact, every pair); not evaluated again. Returns per curve (valid, lowest
    evaluated clearance, its pair, its parameter, evaluations)."""
    lowest = np.full(count, np.inf)
    where = np.zeros(count)
    pair: list[tuple[str, str]] = [("", "")] * count
    evaluations = np.zeros(count, dtype=int)
    valid = np.ones(count, dtype=bool)
    columns: dict[tuple[str, str], int] = {}
    travel = np.zeros((0, world.model.nv))
    mapped: list[tuple[tuple[tuple[str, str], ...], np.ndarray]] = []  # the engine's pair names, their columns

    def record(
        curve: np.ndarray,
        s: np.ndarray,
        pairs: tuple[tuple[str, str], ...],
        distance: np.ndarray,
        rows: np.ndarray,
        count: bool = True,
    ) -> np.ndarray:
        """Distances (len(s), P) of evaluated ``pairs`` (their travel ``rows``) at the parameters; records the
        lowest per curve and fails curves below required."""
        nonlocal travel
        if mapped and (mapped[0][0] is pairs or mapped[0][0] == pairs):  # the same names: map them once
            index = mapped[0][1]
        else:
            index = np.array([columns.setdefault(p, len(columns)) for p in pairs], dtype=int)
            mapped[:] = [(pairs, index)]
            if len(columns) > len(travel):
                travel = np.vstack([travel, np.zeros((len(columns) - len(travel), travel.shape[1]))])
            travel[index] = rows
        d = np.full((len(s), len(columns)), np.inf)  # a pair absent at a configuration: nothing there
        d[:, index] = distance
        if count:
            np.add.at(evaluations, curve, 1)
        if d.shape[1]:
            k = np.argmin(d, axis=1)
            low = d[np.arange(len(s)), k]
            for row in np.flatnonzero(low < lowest[curve]):
                c = curve[row]
                if low[row] < lowest[c]:
                    lowest[c], where[c], pair[c] = low[row], s[row], pairs[np.flatnonzero(index == k[row])[0]]
            valid[curve[low < required]] = False
        return d

    def evaluate(curve: np.ndarray, s: np.ndarray, needed: np.ndarray | None = None) -> np.ndarray:
        """Distances at the parameters: every pair, or only the columns ``needed`` (the others +inf: certified on
        every interval being split, so on each of its pieces) where the world evaluates a subset."""
        Q = configurations(curve, s)
        names = list(columns)
        pairs = None if needed is None else tuple(names[k] for k in needed.tolist())
        found = world.pair_distances(Q, pairs, bound_beyond=BOUND_BEYOND)  # distances only, no witness points
        if found is not None:
            return record(curve, s, found.pairs, found.distance, found.travel)
        batch = world.distance_matrix(Q, bound_beyond=BOUND_BEYOND)
        return record(curve, s, batch.pairs, batch.distance, batch.travel)

    def first_level(
        curve: np.ndarray, s: np.ndarray, evaluate: Callable[..., np.ndarray], rate: Callable[..., np.ndarray]
    ) -> np.ndarray:
        """The grid's distances. When some joints stay still along every curve (one arm planned), a pair whose rate
        is 0 along a curve (no moving joint carries either member: the other arm, the torso, the head) keeps its
        distance: evaluated at each curve's first point only, +inf at the others (that value, checked, holds
        along the whole curve); the other pairs everywhere."""
        first = np.concatenate([[0], np.cumsum([len(g) for g in grids])[:-1]])
        ends = np.array([g[-1] for g in grids])
        nv = world.model.nv
        still = ~np.any(rate(np.arange(count), s[first], ends, np.eye(nv)) > 0.0, axis=0)  # joints never moved
        rest = np.setdiff1d(np.arange(len(s)), first)
        if not still.any() or not rest.size:
            return evaluate(curve, s)
        at_first = evaluate(curve[first], s[first])
        moved = np.flatnonzero(np.any(rate(np.arange(count), s[first], ends, travel) > 0.0, axis=0))
        d = np.full((len(s), len(columns)), np.inf)
        d[first] = at_first
        if moved.size:
            d_rest = evaluate(curve[rest], s[rest], moved)
            d = _pad(d, d_rest.shape[1])
            d[rest] = d_rest
        return d

    curve = np.concatenate([np.full(len(g), k) for k, g in enumerate(grids)])
    s = np.concatenate(grids)
    d = first_level(curve, s, evaluate, rate) if known is None else record(curve, s, *known, count=False)
    # the intervals between consecutive grid points of the same curve
    same = curve[:-1] == curve[1:]
    i_curve, a, b = curve[:-1][same], s[:-1][same], s[1:][same]
    d_a, d_b = d[:-1][same], d[1:][same]
    while len(i_curve):
        keep = valid[i_curve]
        i_curve, a, b, d_a, d_b = i_curve[keep], a[keep], b[keep], d_a[keep], d_b[keep]
        if not len(i_curve):
            break
        if time.perf_counter() > deadline:
            valid[i_curve] = False
            break
        P = len(columns)
        d_a, d_b = _pad(d_a, P), _pad(d_b, P)
        r = rate(i_curve, a, b, travel)
        lower = (d_a + d_b - r * (b - a)[:, None]) / 2
        certified = lower > floor if strict else lower >= floor  # (I, P)
        clear = np.all(certified, axis=1)
        fail = ~clear & (b - a >= shortest)
        valid[i_curve[~clear & ~fail]] = False  # too short to split further and still not certified
        i_curve, a, b, d_a, d_b, r = i_curve[fail], a[fail], b[fail], d_a[fail], d_b[fail], r[fail]
        if not len(i_curve):
            break
        # only the pairs not certified on some interval are evaluated at the new points: every other pair keeps its
        # bound on each interval being split, so on each of its pieces (+inf there: nothing more to certify)
        needed = np.flatnonzero(~np.all(certified[fail], axis=0))
        i_curve, a, b, d_a, d_b = _split(
            i_curve, a, b, d_a, d_b, r, floor, functools.partial(evaluate, needed=needed), len(columns)
        )
    return [(bool(valid[k]), float(lowest[k]), pair[k], float(where[k]), int(evaluations[k])) for k in range(count)]


def _split(
    i_curve: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    d_a: np.ndarray,
    d_b: np.ndarray,
    rate: np.ndarray,
    floor: float,
    evaluate: Callable[[np.ndarray, np.ndarray], np.ndarray],
    columns: int,
) -> tuple[np.ndarray, ...]:
    """Split each uncertified interval ``[a, b]`` into equal pieces, all new points in one evaluation: as many
    pieces as its worst pair would need if its distance stayed at the mean of its ends (``rate · h ≤ 2 (d̄ −
    floor)``, times ``SPLIT_SAFETY``), 2 (halving) to ``MAX_PIECES``. One level of several pieces replaces several
    levels of halving (each a batched evaluation); any split is as sound as halving (each piece gets the same
    two-sided bound). Returns the pieces as (curve, a, b, d_a, d_b)."""
    excess = (d_a + d_b) / 2 - floor  # > 0: both ends were evaluated at more than the floor
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.where(excess > 0, rate * (b - a)[:, None] / (2 * excess), np.inf)
    need = np.nan_to_num(need, nan=0.0, posinf=np.inf).max(axis=1, initial=0.0)
    pieces = np.clip(np.ceil(SPLIT_SAFETY * need), 2, MAX_PIECES).astype(int)
    count = len(i_curve)
    # the new points: j / pieces of each interval for j = 1 .. pieces - 1
    inner = pieces - 1
    first_inner = np.cumsum(inner) - inner
    owner = np.repeat(np.arange(count), inner)
    j = np.arange(owner.size) - first_inner[owner] + 1
    m = a[owner] + (b - a)[owner] * (j / pieces[owner])
    d_m = evaluate(i_curve[owner], m)
    d_a, d_b = _pad(d_a, columns), _pad(d_b, columns)
    d_a, d_b, d_m = (_pad(x, d_m.shape[1]) for x in (d_a, d_b, d_m))
    # the pieces: k = 0 .. pieces - 1 of each interval, between its nodes a, m_1 .. m_{pieces-1}, b
    parent = np.repeat(np.arange(count), pieces)
    k = np.arange(parent.size) - (np.cumsum(pieces) - pieces)[parent]
    first, last = k == 0, k == pieces[parent] - 1
    left = np.clip(first_inner[parent] + k - 1, 0, len(m) - 1)
    right = np.clip(first_inner[parent] + k, 0, len(m) - 1)
    new_a = np.where(first, a[parent], m[left])
    new_b = np.where(last, b[parent], m[right])
    new_d_a = np.where(first[:, None], d_a[parent], d_m[left])
    new_d_b = np.where(last[:, None], d_b[parent], d_m[right])
    return i_curve[parent], new_a, new_b, new_d_a, new_d_b


def _pad(d: np.ndarray, columns: int) -> np.ndarray:
    """Distances of pairs first seen later (a pair absent so far): +inf."""
    if d.shape[1] == columns:
        return d
    return np.hstack([d, np.full((len(d), columns - d.shape[1]), np.inf)])


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

    Each pair's distance changes at most at ``rate_p = travel_p · max|q̇|`` (the joint speeds' bounds on the pieces
    in the interval: their Bernstein coefficients, :func:`~taplan.timing._polynomial.derivative_bound`), so over
    ``[t_a, t_b]`` it stays above ``(d_a + d_b − rate_p (t_b − t_a)) / 2``. Windows of
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
    speeds[:, index] = derivative_bound(trajectory, 1)  # a bound of |q̇| per piece and joint [rad/s]
    times = trajectory.times
    base = robot.home.copy() if hold is None else np.asarray(hold, dtype=float).copy()

    def configurations(curve: np.ndarray, t: np.ndarray) -> np.ndarray:
        Q = np.repeat(base[None], len(t), axis=0)
        Q[:, index] = trajectory(t)
        return Q

    padded = np.vstack([speeds, np.zeros((1, robot.nq))])  # reduceat's bounds may name one row past the pieces

    def rate(curve: np.ndarray, t_a: np.ndarray, t_b: np.ndarray, travel: np.ndarray) -> np.ndarray:
        lo = np.maximum(np.searchsorted(times, t_a, side="right") - 1, 0)
        hi = np.maximum(np.searchsorted(times, t_b, side="left"), lo + 1)  # pieces lo .. hi - 1, hi <= len(speeds)
        # the peak of each interval's pieces in one call: reduceat over the bounds (lo_0, hi_0, lo_1, hi_1, ...)
        # reduces rows lo_i .. hi_i - 1 at the even places (lo < hi: never an empty range); the odd ones are unused
        bounds = np.column_stack([lo, hi]).ravel()
        peak = np.maximum.reduceat(padded, bounds, axis=0)[::2] if len(bounds) else np.zeros((0, robot.nq))
        return peak @ travel.T

    start, end = float(times[0]), float(times[-1])
    grid = np.append(np.arange(start, end, LOOKAHEAD), end)
    [(valid, lowest, pair, when, evaluations)] = _certify_batch(
        world,
        1,
        [grid],
        configurations,
        rate,
        floor,
        floor + MIN_CERTIFIED,
        MIN_INTERVAL,
        deadline,
        strict=True,
    )
    timed_out = not valid and time.perf_counter() > deadline
    return Verification(valid, lowest, pair, when, evaluations, timed_out=timed_out)
