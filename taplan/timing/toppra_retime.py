"""Time-optimal retiming through toppra (TOPP-RA) whose output never exceeds the limits.

Method
------
1. **Path.** Waypoints become a :class:`~taplan.timing.path.Path` (C² cubic spline ``q(s)``). Non-zero boundary
   velocities set the spline's end tangents, so the requested velocity is tangent to the path.
2. **Grid.** Every waypoint is a gridpoint and each waypoint interval is split uniformly into
   ``points_per_segment`` parts (at least 128 grid segments in all). toppra's default gridpoint proposal, which costs
   more than the solve itself, is not used.
3. **Constraints.** Joint velocity at the gridpoints (toppra's ``JointVelocityConstraint``) and
   :class:`~taplan.timing.constraints.SegmentLimitConstraint`: velocity and acceleration at the start, middle and end
   of every grid segment, exact for TOPP-RA's piecewise-constant path acceleration.
4. **Exact output.** toppra's ``(s_i, sd_i)`` are integrated exactly with piecewise-constant
   ``sdd = (sd_{i+1}² - sd_i²) / (2 Δs_i)``: ``s(τ)`` is quadratic on each segment, and the cubic spline composed
   with it is a degree-6 polynomial in time. The result is a polynomial :class:`~taplan.trajectory.Trajectory`: no
   re-fitting spline, so nothing overshoots between samples (toppra's ``ParametrizeSpline`` does).
5. **Verification and repair.** The peaks of ``|q̇|`` and ``|q̈|`` are computed exactly on every segment. Residual
   excess (from toppra's forward-pass safety shrink of ``x`` and between the constrained points) is removed by
   uniform time scaling for rest-to-rest motions, or by re-solving with limits tightened by the measured excess
   when boundary velocities are non-zero (scaling would change them).

The result respects every velocity and acceleration limit at every instant up to floating-point rounding.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from math import comb

import numpy as np
import numpy.typing as npt
import toppra
import toppra.algorithm
import toppra.constraint

from taplan._validation import as_vector
from taplan.errors import InvalidInputError, TimingError
from taplan.limits import JointLimits
from taplan.timing._polynomial import compose_quadratic, peak_ratio, time_scaled
from taplan.timing.constraints import PathJerkSpeedConstraint, PathSpeedCap, SegmentLimitConstraint
from taplan.timing.path import Path, drop_duplicates
from taplan.trajectory import Trajectory

__all__ = ["retime", "time_optimal_profile", "PathProfile", "as_path", "DEFAULT_POINTS_PER_SEGMENT"]

logger = logging.getLogger(__name__)

DEFAULT_POINTS_PER_SEGMENT = 16  # grid segments per waypoint interval
MIN_GRID_SEGMENTS = 128  # grid segments in all, for short paths
MAX_REPAIRS = 4  # re-solves when boundary velocities are non-zero
LIMIT_MARGIN = 1e-9  # relative: scaled output peaks at 1 - LIMIT_MARGIN of each limit
TANGENT_TOL = 1e-6  # relative: boundary velocity must be parallel to the path tangent
POSITION_TOL = 1e-9  # [rad]

_toppra_logger = logging.getLogger("toppra")


@dataclass(frozen=True)
class PathProfile:
    """A time parameterisation ``s(t)`` of a path with piecewise-constant path acceleration.

    Attributes:
        path: The geometric path.
        gridpoints: Path positions s_i, shape (M+1,).
        sd: Path speed ds/dt at the gridpoints [1/s], shape (M+1,).
        sdd: Path acceleration on each grid segment [1/s²], shape (M,).
        times: Time at each gridpoint [s], shape (M+1,), from 0.
    """

    path: Path
    gridpoints: np.ndarray
    sd: np.ndarray
    sdd: np.ndarray
    times: np.ndarray

    @property
    def duration(self) -> float:
        """[s]."""
        return float(self.times[-1])

    def to_trajectory(self, joint_names: tuple[str, ...] | None = None) -> Trajectory:
        """The exact joint trajectory ``q(s(t))`` as degree-6 polynomials in time."""
        path = self.path
        piece = path.piece_index(self.gridpoints[:-1])
        cubic = path.piece_coefficients()[piece]
        sigma = np.column_stack([self.gridpoints[:-1] - path.ss_waypoints[piece], self.sd[:-1], 0.5 * self.sdd])
        return Trajectory.from_polynomials(self.times, compose_quadratic(cubic, sigma), joint_names)


def as_path(
    path_or_waypoints: Path | npt.ArrayLike,
    dof: int,
    start_velocity: np.ndarray | None = None,
    end_velocity: np.ndarray | None = None,
    *,
    limits: JointLimits | None = None,
) -> tuple[Path, float, float]:
    """The path to retime and the boundary path speeds (sd_start, sd_end) matching the boundary joint velocities.

    Waypoints become a :class:`Path` without repeated waypoints; with ``limits`` it stays inside their position
    bounds (a waypoint outside them raises :class:`TimingError`, naming it).
    """
    if isinstance(path_or_waypoints, Path):
        path = path_or_waypoints
        if path.dof != dof:
            raise InvalidInputError("path", f"{path.dof} joints", f"{dof} joints, like the limits")
    else:
        q = drop_duplicates(path_or_waypoints, "path_or_waypoints", dof)
        bounds = None if limits is None else _position_box(q, limits)
        # uniform knots spanning the chord length: |q'| about 1, so TOPP-RA's path speeds stay well scaled for a
        # path of micro-radians as for one of radians (toppra fails on the former with s in [0, 1])
        length = float(np.sum(np.linalg.norm(np.diff(q, axis=0), axis=1)))
        ss = np.linspace(0.0, length, len(q))
        tangents = []
        for v, (i, j) in ((start_velocity, (0, 1)), (end_velocity, (-2, -1))):
            if v is None or not np.any(v):
                tangents.append(None)
                continue
            scale = np.linalg.norm(q[j] - q[i]) / (ss[1] - ss[0])  # |q'| of the end chord
            tangents.append(v / np.linalg.norm(v) * scale)
        path = Path(q, ss, start_tangent=tangents[0], end_tangent=tangents[1], bounds=bounds)
    s0, s1 = path.path_interval
    sd_start = _path_speed(path, s0, start_velocity, "start_velocity")
    return path, sd_start, _path_speed(path, s1, end_velocity, "end_velocity")


def _position_box(q: np.ndarray, limits: JointLimits) -> tuple[np.ndarray, np.ndarray]:
    """The box the path must stay in: the position limits, widened by rounding-size excursions of the waypoints."""
    over = np.maximum(q - limits.upper, limits.lower - q)
    if np.any(over > POSITION_TOL):
        k, j = np.unravel_index(int(np.argmax(over)), over.shape)
        raise TimingError(
            f"waypoint {k} is outside the position limits: {limits.names[j]} = {q[k, j]:.9g} rad "
            f"(limits [{limits.lower[j]:.9g}, {limits.upper[j]:.9g}]); no trajectory through it is within the limits"
        )
    return np.minimum(limits.lower, q.min(axis=0)), np.maximum(limits.upper, q.max(axis=0))


def _path_speed(path: Path, s: float, velocity: np.ndarray | None, name: str) -> float:
    if velocity is None or not np.any(velocity):
        return 0.0
    tangent = path(s, 1)
    speed = float(velocity @ tangent / (tangent @ tangent))
    residual = np.linalg.norm(velocity - speed * tangent)
    if speed <= 0.0 or residual > TANGENT_TOL * np.linalg.norm(velocity):
        raise InvalidInputError(
            name,
            velocity,
            f"a velocity along the path's {'start' if name.startswith('start') else 'end'} tangent "
            f"{np.round(tangent / np.linalg.norm(tangent), 4).tolist()} (pass waypoints to make the path fit it)",
        )
    return speed


def grid_for(
    path: Path, points_per_segment: int = DEFAULT_POINTS_PER_SEGMENT, min_grid_segments: int = MIN_GRID_SEGMENTS
) -> np.ndarray:
    """The TOPP-RA gridpoints taplan uses for ``path``: every waypoint, each interval split uniformly into
    ``points_per_segment`` parts, or more when that makes fewer than ``min_grid_segments`` in all."""
    return _grid(path, points_per_segment, min_grid_segments)


def _grid(path: Path, points_per_segment: int, min_grid_segments: int = MIN_GRID_SEGMENTS) -> np.ndarray:
    ss = path.ss_waypoints
    k = max(int(points_per_segment), int(np.ceil(min_grid_segments / (len(ss) - 1))))
    fractions = np.arange(k) / k
    grid = (ss[:-1, None] + np.diff(ss)[:, None] * fractions[None, :]).ravel()
    return np.append(grid, ss[-1])


def time_optimal_profile(
    path: Path,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    sd_start: float = 0.0,
    sd_end: float = 0.0,
    *,
    points_per_segment: int = DEFAULT_POINTS_PER_SEGMENT,
    jerk: np.ndarray | None = None,
    jerk_fraction: float = 0.5,
    limit_scale: np.ndarray | None = None,
    max_path_speed: float | None = None,
    min_grid_segments: int = MIN_GRID_SEGMENTS,
) -> PathProfile:
    """Solve TOPP-RA with toppra on taplan's grid and integrate the result exactly.

    Args:
        path: Geometric path.
        velocity: Maximum |q̇| [rad]/[s], shape (n,).
        acceleration: Maximum |q̈| [rad]/[s]², shape (n,).
        sd_start: Path speed at the start [1/s].
        sd_end: Path speed at the end [1/s].
        points_per_segment: Grid segments per waypoint interval.
        jerk: Maximum |jerk| [rad]/[s]^3, shape (n,), or None. When given, the path speed is bounded so that the
            speed-only jerk term ``q'''(s) sd^3`` uses at most ``jerk_fraction`` of it.
        jerk_fraction: See ``jerk``.
        limit_scale: Per-gridpoint factor in (0, 1] on the velocity and acceleration limits, shape (M+1,) for the
            grid :func:`grid_for` returns, or None.
        max_path_speed: Upper bound on the path speed ``ṡ`` [unit s / s], or None (e.g. 1 for a path parametrised
            by a recording's time: never faster than the recording).
        min_grid_segments: Fewest grid segments in all (more per interval on a path of few waypoints).

    Raises:
        TimingError: toppra found no parameterisation; the message says why.
    """
    grid = _grid(path, points_per_segment, min_grid_segments)
    constraints = [SegmentLimitConstraint(velocity, acceleration, scale=limit_scale)]
    if jerk is not None:
        constraints.append(PathJerkSpeedConstraint(jerk, jerk_fraction))
    if max_path_speed is not None:
        constraints.append(PathSpeedCap(max_path_speed))
    level = _toppra_logger.level
    _toppra_logger.setLevel(logging.ERROR)
    try:
        instance = toppra.algorithm.TOPPRA(constraints, path, gridpoints=grid, solver_wrapper="seidel")
        sdd, sd, _, K = instance.compute_parameterization(sd_start, sd_end, return_data=True)
    finally:
        _toppra_logger.setLevel(level)
    if sd is None or np.any(~np.isfinite(sd)):
        raise TimingError(_failure_reason(K, sd_start, sd_end, instance))
    x = np.maximum(sd, 0.0) ** 2
    ds = np.diff(grid)
    u = (x[1:] - x[:-1]) / (2.0 * ds)
    speed_sum = sd[:-1] + sd[1:]
    if np.any(speed_sum <= 0.0):
        k = int(np.argmax(speed_sum <= 0.0))
        raise TimingError(f"TOPP-RA stops on the path at s={grid[k]:.6g}: the path cannot be traversed there")
    dt = 2.0 * ds / speed_sum
    times = np.concatenate([[0.0], np.cumsum(dt)])
    return PathProfile(path, grid, np.sqrt(x), u, times)


def _failure_reason(K: np.ndarray | None, sd_start: float, sd_end: float, instance: object) -> str:
    code = getattr(getattr(instance, "problem_data", None), "return_code", None)
    if K is None or np.isnan(K).any():
        if K is not None and np.isnan(K[-1]).any() and sd_end > 0:
            return f"TOPP-RA failed ({code}): end path speed {sd_end:.6g} is not reachable under the limits"
        return (
            f"TOPP-RA failed ({code}): the path is not controllable under the limits "
            "(end velocity too high, or limits too tight for the path's curvature)"
        )
    if not (K[0, 0] - 1e-9 <= sd_start**2 <= K[0, 1] + 1e-9):
        return (
            f"TOPP-RA failed ({code}): start path speed {sd_start:.6g} is outside the controllable range "
            f"[{np.sqrt(max(K[0, 0], 0)):.6g}, {np.sqrt(max(K[0, 1], 0)):.6g}] (start velocity too high to stop or "
            "follow the path within the limits)"
        )
    return f"TOPP-RA failed ({code}): numerical failure in the forward pass"


def max_velocity_acceleration(traj: Trajectory, velocity: np.ndarray, acceleration: np.ndarray) -> tuple[float, float]:
    """Peaks of ``|q̇| / velocity`` and ``|q̈| / acceleration`` over the whole trajectory: exact when above 1, at most
    1 otherwise (:func:`~taplan.timing._polynomial.peak_ratio`: whether and how much to scale is exact)."""
    rv = float(np.max(peak_ratio(traj, 1, velocity), initial=0.0))
    ra = float(np.max(peak_ratio(traj, 2, acceleration), initial=0.0))
    return rv, ra


def retime(
    path_or_waypoints: Path | npt.ArrayLike,
    limits: JointLimits,
    *,
    start_velocity: npt.ArrayLike | None = None,
    end_velocity: npt.ArrayLike | None = None,
    points_per_segment: int = DEFAULT_POINTS_PER_SEGMENT,
    check_positions: bool = True,
) -> Trajectory:
    """Time-optimal trajectory along a path under joint velocity and acceleration limits (TOPP-RA via toppra).

    The returned trajectory never exceeds ``limits.velocity`` or ``limits.acceleration`` at any instant (it is
    verified exactly on its polynomial segments and repaired), so sampling it at any rate stays within the limits.

    Args:
        path_or_waypoints: A :class:`~taplan.timing.path.Path`, or joint waypoints [rad] of shape (N, n), N >= 2,
            in ``limits.names`` order, no two consecutive equal.
        limits: Joint limits (n joints); velocity [rad]/[s] and acceleration [rad]/[s]² are used, positions are
            checked.
        start_velocity: Joint velocity at the start [rad]/[s], shape (n,); default zero. With waypoints, the path is
            bent to start along it; with a ``Path`` it must be tangent to the path.
        end_velocity: Joint velocity at the end [rad]/[s], shape (n,); default zero.
        points_per_segment: TOPP-RA grid segments per waypoint interval (more: closer to optimal, slower).
        check_positions: Raise when the path leaves ``[limits.lower, limits.upper]``.

    Returns:
        A polynomial :class:`~taplan.trajectory.Trajectory` with ``limits.names``, starting at t = 0.

    Raises:
        InvalidInputError: malformed waypoints (NaN, one waypoint, duplicates, wrong shape) or boundary velocities.
        TimingError: no feasible timing (the message says why), or the path leaves the position limits.
    """
    if not isinstance(limits, JointLimits):
        raise InvalidInputError("limits", type(limits).__name__, "a taplan.JointLimits")
    n = limits.size
    v0 = None if start_velocity is None else as_vector(start_velocity, "start_velocity", n)
    v1 = None if end_velocity is None else as_vector(end_velocity, "end_velocity", n)
    if int(points_per_segment) < 1:
        raise InvalidInputError("points_per_segment", points_per_segment, "an integer >= 1")
    for name, v in (("start_velocity", v0), ("end_velocity", v1)):
        if v is not None and np.any(np.abs(v) > limits.velocity * (1 + 1e-9)):
            j = int(np.argmax(np.abs(v) / limits.velocity))
            raise TimingError(
                f"{name}[{limits.names[j]}] = {v[j]:.6g} rad/s exceeds the velocity limit {limits.velocity[j]:.6g}"
            )
    path, sd0, sd1 = as_path(path_or_waypoints, n, v0, v1, limits=limits if check_positions else None)
    if check_positions:
        check_path_positions(path, limits)
    velocity = np.array(limits.velocity, dtype=float)
    acceleration = np.array(limits.acceleration, dtype=float)
    rest = sd0 == 0.0 and sd1 == 0.0
    vel_k, acc_k = velocity.copy(), acceleration.copy()
    for _ in range(MAX_REPAIRS + 1):
        profile = time_optimal_profile(path, vel_k, acc_k, sd0, sd1, points_per_segment=points_per_segment)
        traj = profile.to_trajectory(limits.names)
        rv, ra = max_velocity_acceleration(traj, velocity, acceleration)
        if rv <= 1.0 and ra <= 1.0:
            return traj
        if rest:
            factor = max(1.0, rv, np.sqrt(ra)) * (1.0 + LIMIT_MARGIN)
            logger.debug("retime: scaling time by %.6f (velocity %.6f, acceleration %.6f of limits)", factor, rv, ra)
            return time_scaled(traj, factor)
        vel_k = vel_k / max(1.0, rv * (1 + 1e-6))
        acc_k = acc_k / max(1.0, ra * (1 + 1e-6))
    raise TimingError(
        f"retime: could not bring the trajectory within the limits after {MAX_REPAIRS} repairs "
        f"(velocity {rv:.6f}, acceleration {ra:.6f} of the limits) with non-zero boundary velocities"
    )


def check_path_positions(path: Path, limits: JointLimits) -> None:
    """Raise :class:`TimingError` when the path leaves the position limits (exact: Bernstein hulls, then the real
    extrema of the pieces whose hull crosses a bound)."""
    ss = path.ss_waypoints
    c = path.piece_coefficients()  # (m, d+1, n)
    h = np.diff(ss)
    degree = c.shape[1] - 1
    # Bernstein coefficients of each piece on [0, h]: b_k = sum_{i<=k} C(k,i)/C(d,i) a_i h^i
    scaled = c * (h[:, None] ** np.arange(degree + 1))[:, :, None]
    weights = np.array(
        [[comb(k, i) / comb(degree, i) if i <= k else 0.0 for i in range(degree + 1)] for k in range(degree + 1)]
    )
    hull = np.einsum("ki,min->mkn", weights, scaled)
    suspect = np.argwhere(
        (hull.max(axis=1) > limits.upper + POSITION_TOL) | (hull.min(axis=1) < limits.lower - POSITION_TOL)
    )
    worst = (0.0, 0.0, 0, 0.0)
    for m, j in suspect:
        poly = np.polynomial.Polynomial(c[m, :, j])
        roots = poly.deriv().roots()
        x = np.concatenate(
            [[0.0, h[m]], roots[(np.abs(roots.imag) < 1e-12) & (roots.real >= 0) & (roots.real <= h[m])].real]
        )
        values = poly(x)
        for value, xi in zip(values, x, strict=True):
            over = max(value - limits.upper[j], limits.lower[j] - value)
            if over > worst[0]:
                worst = (over, float(value), int(j), float(ss[m] + xi))
    if worst[0] > POSITION_TOL:
        _, value, j, s = worst
        raise TimingError(
            f"the path leaves the position limits: {limits.names[j]} = {value:.6g} rad at s={s:.6g} "
            f"(limits [{limits.lower[j]:.6g}, {limits.upper[j]:.6g}]); pass waypoints (taplan then builds a path "
            "that stays inside) or a Path built with bounds"
        )
