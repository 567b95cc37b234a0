"""Trajectory optimisation with casadi (ipopt): minimum time or minimum jerk through waypoints, joint space only.

Formulation
-----------
Every waypoint segment ``s`` (``W - 1`` of them) is split into ``N = intervals`` intervals of equal duration
``h_s = T_s / N``; on each interval the jerk ``j_k`` is constant (piecewise-constant jerk). The state
``(q, q̇, q̈)`` at the knots follows the exact triple-integrator update

.. math::

    q_{k+1} = q_k + h \\dot q_k + \\tfrac{h^2}{2} \\ddot q_k + \\tfrac{h^3}{6} j_k, \\quad
    \\dot q_{k+1} = \\dot q_k + h \\ddot q_k + \\tfrac{h^2}{2} j_k, \\quad
    \\ddot q_{k+1} = \\ddot q_k + h j_k,

so the result is an exact cubic per interval. Constraints: rest at both ends (``q̇ = q̈ = 0``), the first and last
waypoint exactly, each intermediate waypoint exactly or within a box ``|q(t_s) - w_s| <= tolerance``, and the
bounds ``lower <= q <= upper`` (at knots), ``|q̇| <= v`` (at knots and interval midpoints), ``|q̈| <= a``
(at knots: it is linear in between, so this is exact) and ``|j| <= jerk`` (exact). Variables are scaled by their
limits.

Objectives: ``"time"`` minimises ``Σ T_s`` (plus a tiny jerk regulariser for uniqueness); ``"jerk"`` minimises
``∫ Σ_i (j_i / jerk_i)² dt`` at a fixed total duration (default: the warm start's), the segment durations free.

Warm start: the jerk-limited trajectory (:func:`~taplan.timing.jerk_limited.jerk_limited`, or TOPP-RA
:func:`~taplan.timing.toppra_retime.retime` with ``warm_start="topp"``), sampled at the knots; its waypoint
times give ``T_s``.

Verification: the velocity peak inside an interval (a quadratic) can exceed the knot/midpoint values; the output is
checked exactly on its polynomials (:func:`~taplan.timing.limits_check.limit_usage`). An excess of at most
``RESCUE_EXCESS`` is removed by uniform time scaling (recorded in ``OptimizationResult.time_scale``); anything larger,
a position outside the bounds, a waypoint missed, or an ipopt failure raises :class:`~taplan.errors.TimingError`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np
import numpy.typing as npt

from taplan.errors import InvalidInputError, TimingError, UnknownNameError
from taplan.limits import JointLimits
from taplan.timing._polynomial import time_scaled
from taplan.timing.limits_check import LimitUsage, limit_usage
from taplan.timing.path import validate_waypoints
from taplan.trajectory import Trajectory

__all__ = ["OptimizationResult", "optimize", "OBJECTIVES", "DEFAULT_INTERVALS"]

OBJECTIVES = ("time", "jerk")
_WARM_STARTS = ("jerk", "topp")
DEFAULT_INTERVALS = 10  # constant-jerk intervals per waypoint segment
DEFAULT_MAX_ITERATIONS = 1000
LIMIT_TOL = 1e-6  # relative: allowed excess of a bound after solving (floating point and ipopt tolerance)
POSITION_TOL = 1e-6  # [rad] allowed excess of a position bound and of a waypoint box
RESCUE_EXCESS = 0.02  # relative: an excess up to this much is removed by time scaling, more raises
REGULARISATION = 1e-4  # weight of the jerk regulariser in the minimum-time objective
_WARM_RATE = 2000.0  # [Hz] sampling of the warm start to find its waypoint times


@dataclass(frozen=True)
class OptimizationResult:
    """An optimised trajectory and how it was obtained.

    Attributes:
        trajectory: Cubic per interval, starts at t = 0, joint names of the limits.
        objective: ``"time"`` or ``"jerk"``.
        waypoint_times: Time at which each waypoint (or its box) is reached [s], shape (W,).
        waypoint_error: Largest ``|q(t_s) - w_s|`` over the waypoints and joints [rad].
        warm_start: The warm-start trajectory.
        usage: Exact peak ``|derivative| / limit`` of the result.
        solve_time: Wall-clock time of the ipopt solve [s].
        iterations: ipopt iterations.
        status: ipopt's return status.
        time_scale: Uniform time scaling applied after solving (1.0 when the solution held every bound).
        cost: Final objective value (``"jerk"``: ``∫ Σ (j/jerk)² dt`` [s]; ``"time"``: duration plus regulariser).
    """

    trajectory: Trajectory
    objective: str
    waypoint_times: np.ndarray
    waypoint_error: float
    warm_start: Trajectory
    usage: LimitUsage
    solve_time: float
    iterations: int
    status: str
    time_scale: float
    cost: float

    @property
    def duration(self) -> float:
        """[s]."""
        return self.trajectory.duration


def _waypoint_times(traj: Trajectory, q: np.ndarray) -> np.ndarray:
    """Times at which ``traj`` passes each waypoint (closest sample, in order)."""
    t = traj.sample_times(_WARM_RATE)
    x = traj(t)
    out = [t[0]]
    start = 0
    for w in q[1:-1]:
        d = np.max(np.abs(x[start:] - w), axis=1)
        k = start + int(np.argmin(d))
        out.append(t[k])
        start = k
    out.append(t[-1])
    return np.array(out)


def optimize(
    waypoints: npt.ArrayLike,
    limits: JointLimits,
    *,
    objective: str = "time",
    duration: float | None = None,
    tolerance: float | npt.ArrayLike = 0.0,
    intervals: int = DEFAULT_INTERVALS,
    warm_start: str | Trajectory = "jerk",
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
) -> OptimizationResult:
    """Minimum-time or minimum-jerk rest-to-rest trajectory through (or near) joint waypoints.

    Args:
        waypoints: Joint positions [rad], shape (W, n), W >= 2, in ``limits.names`` order.
        limits: Position, velocity, acceleration and jerk bounds (n joints).
        objective: ``"time"`` (minimum duration) or ``"jerk"`` (minimum integrated squared normalised jerk at a fixed
            ``duration``).
        duration: Total duration for ``"jerk"`` [s]; default the warm start's. Ignored for ``"time"``.
        tolerance: Box half-width around each intermediate waypoint [rad], scalar or shape (n,); 0 = exact.
        intervals: Constant-jerk intervals per waypoint segment.
        warm_start: ``"jerk"`` (jerk-limited), ``"topp"`` (TOPP-RA), or a rest-to-rest Trajectory through the
            waypoints (same joints).
        max_iterations: ipopt iteration limit.

    Returns:
        The optimised trajectory with diagnostics.

    Raises:
        InvalidInputError: malformed waypoints or options. UnknownNameError: unknown objective or warm start.
        TimingError: ipopt failed (infeasible duration, iteration limit), or the solution violates a bound or misses
            a waypoint beyond the tolerances.
    """
    if not isinstance(limits, JointLimits):
        raise InvalidInputError("limits", type(limits).__name__, "a taplan.JointLimits")
    n = limits.size
    q_way = validate_waypoints(waypoints, "waypoints", n)
    if objective not in OBJECTIVES:
        raise UnknownNameError("objective", objective, OBJECTIVES)
    if int(intervals) != intervals or int(intervals) < 1:
        raise InvalidInputError("intervals", intervals, "an integer >= 1")
    if int(max_iterations) < 1:
        raise InvalidInputError("max_iterations", max_iterations, "an integer >= 1")
    tol = np.broadcast_to(np.asarray(tolerance, dtype=float), (n,)) if np.ndim(tolerance) == 0 else None
    if tol is None:
        tol = np.asarray(tolerance, dtype=float)
        if tol.shape != (n,):
            raise InvalidInputError("tolerance", f"shape {tol.shape}", f"a scalar or shape ({n},)")
    if not np.all(np.isfinite(tol)) or np.any(tol < 0):
        raise InvalidInputError("tolerance", tolerance, "finite values >= 0 [rad]")
    if duration is not None and (not np.isfinite(duration) or duration <= 0):
        raise InvalidInputError("duration", duration, "a finite duration > 0 [s] or None")
    outside = (q_way < limits.lower) | (q_way > limits.upper)
    if np.any(outside):
        i, j = np.argwhere(outside)[0]
        raise InvalidInputError(
            f"waypoints[{i}]", f"{limits.names[j]} = {q_way[i, j]:.6g}", "positions within the limits' bounds"
        )

    warm = _warm_start(q_way, limits, warm_start)
    t_way = _waypoint_times(warm, q_way)
    seg_warm = np.maximum(np.diff(t_way), 1e-3)
    total = float(duration) if (objective == "jerk" and duration is not None) else warm.duration

    W, N = len(q_way), int(intervals)
    S, M = W - 1, (W - 1) * int(intervals)
    vmax, amax, jmax = (np.asarray(getattr(limits, f), dtype=float) for f in ("velocity", "acceleration", "jerk"))
    opti = ca.Opti()
    Q = opti.variable(n, M + 1)  # [rad]
    V = opti.variable(n, M + 1)  # scaled by vmax
    A = opti.variable(n, M + 1)  # scaled by amax
    U = opti.variable(n, M)  # scaled by jmax
    T = opti.variable(S)  # segment durations [s]
    vs, as_, js = (ca.DM(x) for x in (vmax, amax, jmax))
    for k in range(M):
        h = T[k // N] / N
        q, v, a, u = Q[:, k], vs * V[:, k], as_ * A[:, k], js * U[:, k]
        opti.subject_to(Q[:, k + 1] == q + h * v + h**2 / 2 * a + h**3 / 6 * u)
        opti.subject_to(vs * V[:, k + 1] == v + h * a + h**2 / 2 * u)
        opti.subject_to(as_ * A[:, k + 1] == a + h * u)
        mid = v + h / 2 * a + h**2 / 8 * u  # velocity at the interval midpoint
        opti.subject_to(opti.bounded(-vs, mid, vs))
    opti.subject_to(opti.bounded(-1, V, 1))
    opti.subject_to(opti.bounded(-1, A, 1))
    opti.subject_to(opti.bounded(-1, U, 1))
    lo, hi = ca.DM(limits.lower), ca.DM(limits.upper)
    for k in range(M + 1):
        opti.subject_to(opti.bounded(lo, Q[:, k], hi))
    for end in (0, M):
        opti.subject_to(Q[:, end] == q_way[0 if end == 0 else -1])
        opti.subject_to(V[:, end] == 0)
        opti.subject_to(A[:, end] == 0)
    for s in range(1, S):
        if np.any(tol > 0):
            opti.subject_to(opti.bounded(ca.DM(q_way[s] - tol), Q[:, s * N], ca.DM(q_way[s] + tol)))
        else:
            opti.subject_to(Q[:, s * N] == q_way[s])
    opti.subject_to(opti.bounded(1e-3 * seg_warm.min() / N, T, 20.0 * total))
    jerk_cost = sum(T[k // N] / N * ca.sumsqr(U[:, k]) for k in range(M))
    if objective == "time":
        opti.minimize(ca.sum1(T) / total + REGULARISATION * jerk_cost / (total * n))
    else:
        opti.subject_to(ca.sum1(T) == total)
        opti.minimize(jerk_cost)

    # warm start: the warm trajectory's state at the knots of its own waypoint times
    seg0 = seg_warm * (total / seg_warm.sum()) if objective == "jerk" else seg_warm
    knots = np.concatenate([[0.0], np.repeat(seg0 / N, N).cumsum()])
    tw = np.clip(knots * (warm.duration / knots[-1]), 0.0, warm.duration)
    scale = warm.duration / knots[-1]  # > 1 when the requested duration is shorter than the warm start
    opti.set_initial(Q, warm(tw).T)
    opti.set_initial(V, (warm(tw, 1) * scale / vmax).T)
    opti.set_initial(A, (warm(tw, 2) * scale**2 / amax).T)
    acc = warm(tw, 2) * scale**2
    opti.set_initial(U, np.clip((np.diff(acc, axis=0) / np.diff(knots)[:, None] / jmax).T, -1, 1))
    opti.set_initial(T, seg0)
    opti.solver(
        "ipopt",
        {"print_time": False},
        {"print_level": 0, "max_iter": int(max_iterations), "tol": 1e-9, "acceptable_tol": 1e-7, "sb": "yes"},
    )
    start = time.perf_counter()
    try:
        sol = opti.solve()
    except RuntimeError as exc:
        stats = opti.stats()
        raise TimingError(
            f"optimize ({objective}): ipopt failed with status {stats.get('return_status', '?')!r} after "
            f"{stats.get('iter_count', '?')} iterations ({str(exc).splitlines()[0]}); e.g. the duration is too "
            "short for the limits, or the waypoints leave no feasible motion"
        ) from None
    solve_time = time.perf_counter() - start
    stats = sol.stats()
    q_k = np.asarray(sol.value(Q)).reshape(n, M + 1).T
    v_k = (np.asarray(sol.value(V)).reshape(n, M + 1) * vmax[:, None]).T
    a_k = (np.asarray(sol.value(A)).reshape(n, M + 1) * amax[:, None]).T
    u_k = (np.asarray(sol.value(U)).reshape(n, M) * jmax[:, None]).T
    seg = np.atleast_1d(np.asarray(sol.value(T), dtype=float))
    h = np.repeat(seg / N, N)
    times = np.concatenate([[0.0], np.cumsum(h)])
    coefficients = np.stack([q_k[:-1], v_k[:-1], a_k[:-1] / 2, u_k / 6], axis=1)  # (M, 4, n)
    try:
        traj = Trajectory.from_polynomials(times, coefficients, limits.names, continuity_tol=1e-5)
    except InvalidInputError as exc:
        raise TimingError(f"optimize ({objective}): the solution is not continuous ({exc})") from None
    return _verified(traj, limits, q_way, tol, objective, warm, times[::N], solve_time, stats, sol.value(opti.f))


def _warm_start(q: np.ndarray, limits: JointLimits, warm_start: str | Trajectory) -> Trajectory:
    if isinstance(warm_start, Trajectory):
        if tuple(warm_start.joint_names) != tuple(limits.names):
            raise InvalidInputError("warm_start", warm_start.joint_names, f"a trajectory over {limits.names}")
        return warm_start.shifted(-warm_start.times[0])
    if warm_start not in _WARM_STARTS:
        raise UnknownNameError("warm_start", warm_start, _WARM_STARTS)
    if warm_start == "jerk":
        from taplan.timing.jerk_limited import jerk_limited

        return jerk_limited(q, limits).trajectory
    from taplan.timing.toppra_retime import retime

    return retime(q, limits)


def _verified(
    traj: Trajectory,
    limits: JointLimits,
    q_way: np.ndarray,
    tol: np.ndarray,
    objective: str,
    warm: Trajectory,
    t_way: np.ndarray,
    solve_time: float,
    stats: dict,
    cost: float,
) -> OptimizationResult:
    usage = limit_usage(traj, limits)
    ratio = max(usage.max_velocity, np.sqrt(usage.max_acceleration), np.cbrt(usage.max_jerk))
    scale = 1.0
    if ratio > 1.0 + LIMIT_TOL:
        if ratio > 1.0 + RESCUE_EXCESS:
            raise TimingError(
                f"optimize ({objective}): the solution exceeds the limits (velocity {usage.max_velocity:.6f}, "
                f"acceleration {usage.max_acceleration:.6f}, jerk {usage.max_jerk:.6f} of the limits)"
            )
        scale = float(ratio) * (1.0 + 1e-9)
        traj = time_scaled(traj, scale)
        t_way = t_way * scale
        usage = limit_usage(traj, limits)
    if float(usage.position.max()) > POSITION_TOL:
        j = int(np.argmax(usage.position))
        raise TimingError(
            f"optimize ({objective}): {limits.names[j]} leaves its position bounds by {usage.position[j]:.3g} rad"
        )
    err = np.abs(traj(t_way) - q_way)
    excess = err - tol[None, :]
    if float(excess.max()) > POSITION_TOL:
        s, j = np.unravel_index(int(np.argmax(excess)), excess.shape)
        raise TimingError(
            f"optimize ({objective}): waypoint {s} missed: {limits.names[j]} off by {err[s, j]:.3g} rad "
            f"(tolerance {tol[j]:.3g})"
        )
    return OptimizationResult(
        trajectory=traj,
        objective=objective,
        waypoint_times=t_way,
        waypoint_error=float(err.max()),
        warm_start=warm,
        usage=usage,
        solve_time=solve_time,
        iterations=int(stats.get("iter_count", -1)),
        status=str(stats.get("return_status", "")),
        time_scale=scale,
        cost=float(cost),
    )
